"""``rgbd_tracker_node``: two-step direct RGB-D tracking, frame-to-frame then against the relit reference (§III-D)."""
