"""apps package of nearsub."""
