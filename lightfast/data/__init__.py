"""Converters from public datasets to rosbag2 MCAP recordings that the nodes and tests replay."""
