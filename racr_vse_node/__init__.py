"""``racr_vse_node``: the VSE (visual SLAM engine) stand-in of a live rACR run (paper §3.3, §5.1)."""
