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

# vtr_localizer_node (colour-constant stereo VT&R, paper 3 §IV): rectified stereo input, localization output
STEREO_LEFT_IMAGE_TOPIC = "/stereo/left/image_raw"
STEREO_RIGHT_IMAGE_TOPIC = "/stereo/right/image_raw"
STEREO_LEFT_INFO_TOPIC = "/stereo/left/camera_info"
STEREO_RIGHT_INFO_TOPIC = "/stereo/right/camera_info"
STEREO_LEFT_FRAME = "stereo_left_optical_frame"
STEREO_RIGHT_FRAME = "stereo_right_optical_frame"
VTR_LOCALIZATION_TOPIC = "/vtr/localization"
VTR_ODOMETRY_TOPIC = "/vtr/odometry"
VTR_STATUS_TOPIC = "/vtr/status"
VTR_FV_TOPIC = "/vtr/color_constant/fv"
VTR_FR_TOPIC = "/vtr/color_constant/fr"
VTR_FINISH_TEACH_SERVICE = "/vtr/finish_teach"  # std_srvs/srv/Trigger
VTR_ODOM_FRAME = "vtr_odom"  # origin of the VO chain: the left camera of the first frame processed
VTR_KEYFRAME_FRAME_PREFIX = "vtr_keyframe_"  # + keyframe index: the left camera frame of a taught keyframe
