"""Topic names and frame ids shared by the converters, simulators and nodes (see the README's topic table)."""

COLOR_TOPIC = "/camera/color/image_raw"
COLOR_INFO_TOPIC = "/camera/color/camera_info"
DEPTH_TOPIC = "/camera/depth/image_raw"
DEPTH_INFO_TOPIC = "/camera/depth/camera_info"
GT_POSE_TOPIC = "/ground_truth/pose"
SUN_DIRECTION_TOPIC = "/sun/direction"
SUN_CHUNK_TOPIC = "/radiosity/sun_chunk"

OPTICAL_FRAME = "camera_color_optical_frame"
MAP_FRAME = "map"
