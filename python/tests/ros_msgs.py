"""grid_map_msgs for rosbags (not in its ROS 2 stores): the .msg texts of the jazzy branch of
ANYbotics/grid_map, comments left out; shared by test_ros2.py and test_sim_record.py."""

GRID = "grid_map_msgs/msg/GridMap"

GRID_MAP_MSG = """std_msgs/Header header
GridMapInfo info
string[] layers
string[] basic_layers
std_msgs/Float32MultiArray[] data
uint16 outer_start_index
uint16 inner_start_index
"""
GRID_MAP_INFO_MSG = """float64 resolution
float64 length_x
float64 length_y
geometry_msgs/Pose pose
"""


def register_grid_map(store, get_types_from_msg):
    """Adds grid_map_msgs/msg/GridMap and GridMapInfo to a rosbags type store."""
    types = {}
    types.update(get_types_from_msg(GRID_MAP_MSG, GRID))
    types.update(get_types_from_msg(GRID_MAP_INFO_MSG, "grid_map_msgs/msg/GridMapInfo"))
    store.register(types)
    return store
