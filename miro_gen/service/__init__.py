"""The service process: what a program that serves or calls objects is, above the transport.
`Server` and `Client` (`server`), the common options they take from the command line
(`options`), the service object every server answers beside its own objects, with its live
parameters (`introspection`), the manual's `Implementation`, the clock of a log player followed
(`log_clock`), and what changes when the process talks to the CORBA world (`iiop`). The
transport below carries its calls, names and events (`miro_gen.transport`)."""
