"""Everything that touches ROS 2: transport set-up, message conversions, QoS, parameters, the bag player and
recorder. Importing this package does not import rclpy; the modules that need it import it themselves.
"""
