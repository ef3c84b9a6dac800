"""Object-in-gripper pose from AprilTags on the wrist camera."""
