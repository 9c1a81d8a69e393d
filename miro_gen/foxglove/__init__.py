"""The robot in Foxglove and Lichtblick: a bridge over the Foxglove SDK's WebSocket server
(`miro foxglove`, `miro log play --foxglove`; docs/FOXGLOVE.md). Needs the `foxglove` extra;
this package's own `__init__` imports nothing of it, so that a parser can show its defaults."""

DEFAULT_PORT = 8765  # Foxglove's default for a WebSocket connection
DEFAULT_BACKLOG = 128  # messages kept per client: a slow one loses the oldest beyond
