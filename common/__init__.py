"""common package of nearsub."""
