"""The viewer's scene model (what the page draws), its page (static files shipped as package data),
and `foxglove`: the same run as Foxglove channels."""
