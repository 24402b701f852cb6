"""``racr_platform_sim_node``: the simulated robotic platform of a live rACR run (paper §3.6, §5.1)."""
