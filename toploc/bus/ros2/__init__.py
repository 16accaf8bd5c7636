"""toploc on a ROS 2 graph over rmw_zenoh, without a ROS installation: the thin part that no
library does, beside the CDR and type hashes that ``rosbags`` does.

A ROS 2 graph over rmw_zenoh (ROS 2 Jazzy, rmw_zenoh 0.2.x; Kilted's is the same) is a Zenoh
network with fixed conventions, written in rmw_zenoh's ``docs/design.md``. Modules, from the
ground up:

- :mod:`~toploc.bus.ros2.keys`: ROS names (fully qualified, mangled) and the data key
  expressions ``<domain>/<name>/<DDS type>/<type hash>`` of topics and services;
- :mod:`~toploc.bus.ros2.attachment`: the 33-byte attachment of every sample, request and reply;
- :mod:`~toploc.bus.ros2.graph`: the liveliness tokens of graph discovery (``@ros2_lv/...``),
  the QoS they encode and the entities' GIDs;
- :mod:`~toploc.bus.ros2.codec`: the message and service types (rosbags' type store for Jazzy,
  std_srvs's services, ``toploc_msgs``), CDR both ways and RIHS01 type hashes as rosidl makes
  them;
- :mod:`~toploc.bus.ros2.messages`: toploc's belief as ROS messages.

The ROS 2 node that uses them is :mod:`toploc.nodes.ros2`. The ``toploc_msgs`` interface
package (``toploc_msgs/``: ``package.xml``, ``CMakeLists.txt``, ``msg/RoomBelief.msg``) ships
as package data here: a ROS user builds it with colcon; toploc reads the same ``.msg`` file.
"""
