"""A cell of robot PCs over Zenoh: key expressions, a peer's Zenoh config, the console's client."""
