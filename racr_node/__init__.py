"""``racr_node``: active camera relocalization by scale-aware point-cloud alignment (paper: rACR, §3)."""
