"""`miro launch`: a robot's services from a launch file (TOML), started in order, kept up and
stopped together. `spec` reads and checks the file, `supervisor` runs one host's part of it,
`tree` owns the services' processes (and its watcher stops them when the launch is killed),
`console` shows the output and the status table, `documents` writes inline parameters as
run-time documents."""
