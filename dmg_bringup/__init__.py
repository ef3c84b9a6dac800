"""Bring-up of the DMG cell: the `dmg` CLI, the node launcher, bag tools and the install layout."""
