"""Remote calls over ZeroMQ: the frames of a call (`frames`), the client side that generated
stubs call through (`invoker`), the server side that serves a process's objects (`adapter`,
its threads in `dispatch`) and who calls (`caller`)."""
