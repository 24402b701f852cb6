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

# daylight_relight_node <-> rgbd_tracker_node (paper §III-C/D)
COARSE_POSE_TOPIC = "/tracker/coarse_pose"
REFERENCE_COLOR_TOPIC = "/relight/reference/color"
REFERENCE_DEPTH_TOPIC = "/relight/reference/depth"
SCALE_TOPIC_PREFIX = "/relight/scale/"  # + component name: brightness scales as Vector3Stamped (x=r, y=g, z=b)
SCALE_SUN_TOPIC = SCALE_TOPIC_PREFIX + "sun"
SCALE_SKY_TOPIC = SCALE_TOPIC_PREFIX + "sky"
SCALE_GROUND_TOPIC = SCALE_TOPIC_PREFIX + "ground"
RELIGHT_STATUS_TOPIC = "/relight/status"
TRACKER_POSE_TOPIC = "/tracker/pose"
TRACKER_ODOMETRY_TOPIC = "/tracker/odometry"
TRACKER_STATUS_TOPIC = "/tracker/status"
TRACKER_RESET_TOPIC = "/tracker/reset"
