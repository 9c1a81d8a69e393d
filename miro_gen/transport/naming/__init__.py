"""Naming: names (paths such as `robot1/ExampleA`) bound to object references. The naming
service (`service`, its rules in `table`, its memory across restarts in `owners_log`), its
clients (`client`), the names a server keeps under leases (`leases`), and finding the service
on the local network (`discovery`). It is served and called as any remote object (`rpc`)."""
