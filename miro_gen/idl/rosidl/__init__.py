"""ROS 2 interfaces: `.msg`, `.srv` and `.action` files, and rosidl's `.idl`, as ROS 2 Kilted's
rosidl reads them, into the resolved AST the rest of miro-idl uses (`unit.compile_ros2`), with
the RIHS01 type hash of every struct."""
