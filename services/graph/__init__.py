"""``arroch graph``: the service graph of :mod:`protocol.graph` as text, JSON, DOT, Markdown or a picture."""
