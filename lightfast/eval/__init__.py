"""Evaluations that reproduce the papers' tables (ROS-free; ground truth is read only here)."""
