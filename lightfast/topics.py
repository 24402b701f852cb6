"""Topic names and frame ids shared by the converters, simulators and nodes (see the README's topic table)."""

COLOR_TOPIC = "/camera/color/image_raw"
COLOR_INFO_TOPIC = "/camera/color/camera_info"
DEPTH_TOPIC = "/camera/depth/image_raw"
DEPTH_INFO_TOPIC = "/camera/depth/camera_info"
GT_POSE_TOPIC = "/ground_truth/pose"
SUN_DIRECTION_TOPIC = "/sun/direction"
SUN_CHUNK_TOPIC = "/radiosity/sun_chunk"

# default frame names (REP 103/105); every node takes the frames it publishes in as parameters
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
INITIAL_POSE_TOPIC = "/initialpose"  # geometry_msgs/PoseWithCovarianceStamped, as RViz's "2D Pose Estimate" sends it

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

# rACR (paper 2, §3): a visual SLAM engine (VSE) and a robotic platform in, racr_node out (README: rACR topics)
VSE_POINTS_TOPIC = "/vse/points"  # PointCloud2 x, y, z (VSE units) + intensity, frame VSE_FRAME
VSE_POSE_TOPIC = "/vse/pose"  # PoseStamped T_vse_cam (VSE units)
VSE_KEYFRAME_IMAGE_TOPIC = "/vse/keyframe/image"  # Image mono8/mono16/32FC1, frame VSE_KEYFRAME_FRAME_PREFIX + id
VSE_KEYFRAME_POSE_TOPIC = "/vse/keyframe/pose"  # TransformStamped VSE_FRAME -> VSE_KEYFRAME_FRAME_PREFIX + id
VSE_CAMERA_INFO_TOPIC = "/vse/camera_info"  # CameraInfo of the keyframe images
VSE_STATUS_TOPIC = "/vse/status"  # DiagnosticArray of the VSE stand-in (racr_vse_node)
VSE_FRAME = "vse"
VSE_KEYFRAME_FRAME_PREFIX = "vse_keyframe_"
PLATFORM_POSE_TOPIC = "/platform/pose"  # PoseStamped T_base_hand as the platform reports it (m)
PLATFORM_STOPPED_TOPIC = "/platform/stopped"  # PoseStamped T_base_hand, once per motion, stamped when at rest
PLATFORM_STATUS_TOPIC = "/platform/status"  # DiagnosticArray
PLATFORM_BASE_FRAME = "platform_base"
PLATFORM_HAND_FRAME = "platform_hand"
PLATFORM_HAND_GOAL_FRAME = "platform_hand_goal"
RACR_HAND_MOTION_TOPIC = "/racr/hand_motion"  # TransformStamped platform_hand -> platform_hand_goal = M_B
RACR_STATUS_TOPIC = "/racr/status"  # DiagnosticArray
RACR_ALIGNED_CLOUD_TOPIC = "/racr/aligned_cloud"  # PointCloud2 in the reference frame (inspection)
RACR_REFERENCE_CLOUD_TOPIC = "/racr/reference_cloud"  # PointCloud2, the loaded reference (inspection)
RACR_CAMERA_POSE_TOPIC = "/racr/camera_pose"  # PoseStamped T_ref_cam, the current camera in the reference frame
# simulator truth: the platform simulator publishes it for the VSE stand-in (which renders from it) and evaluations;
# racr_node never subscribes to it
SIM_CAMERA_POSE_TOPIC = "/sim/ground_truth/camera_pose"  # PoseStamped T_world_cam (true camera pose)
SIM_WORLD_FRAME = "world"
# readiness: each node publishes its name here (std_msgs/String, latched) once it can take data
READY_TOPIC = "/lightfast/ready"
