"""What every rclpy node of the project shares: start-up, parameters from config/, waiting in
callbacks, geometry messages. Only node modules (and the CLI) import this; cores never do."""
