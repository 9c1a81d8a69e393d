"""The live tools' library: running services found through the naming service and their service
objects (`remote`), schemas they give compiled and cached (`schemas`), values from the shell and
back (`values`), and their interfaces as text (`show`). The commands are in miro_gen.cli."""
