"""``daylight_relight_node``: brightness scales and the relit reference colour + depth per live frame (§III-C/D)."""
