"""Shared plumbing at the bottom of the project: configuration, environment, rigid transforms
(ROS-free), and in `dmg_common.ros` what every rclpy node shares (start-up, parameters, waiting,
geometry messages). It imports no other package of the project."""
