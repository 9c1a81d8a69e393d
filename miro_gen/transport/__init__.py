"""The ZeroMQ transport: options, naming, servers, clients, event channels, the reactor."""
