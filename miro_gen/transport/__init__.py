"""The ZeroMQ backbone: remote calls (`rpc`), naming (`naming`) and event channels (`events`),
over the reactor and the sockets beneath them (`reactor`, `sockets`, with the addresses they
bind and advertise, their keys and their ipc:// twins). The service process above it is
`miro_gen.service`. The second backbone, over Eclipse Zenoh, is `zenoh` (docs/FLEET.md)."""
