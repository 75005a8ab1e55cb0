"""tools package of nearsub."""
