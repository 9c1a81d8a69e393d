"""miro's own minimal RTPS participant (wire.py: the bytes; participant.py: UDP on loopback),
for what the cyclonedds wheel cannot do with Fast DDS peers: service replies carrying the
request's sample identity (ros2/rmw_cyclonedds#184)."""
