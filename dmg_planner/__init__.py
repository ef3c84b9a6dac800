"""DMG planner."""
