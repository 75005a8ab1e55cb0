"""The viewer's scene model (what the page draws) and its page (static files shipped as package data)."""
