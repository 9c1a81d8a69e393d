"""ROS 2 without ROS: a miro process on a ROS 2 graph over DDS (the cyclonedds wheel, the
`ros2` extra), as the RMWs of ROS 2 Kilted put nodes, topics and services on it; docs/ROS2.md.

One job per module: `names` (ROS names on the wire), `qos` (profiles), `domain` (the
participant), `schema`, `xtypes` and `typeinfo` (a generated type described to DDS),
`endpoints` (readers and writers of CDR bytes, the delivering thread), `graph`
(`ros_discovery_info`, discovery), `node` (nodes, publishers, subscriptions), `services`
(services and clients).
"""
