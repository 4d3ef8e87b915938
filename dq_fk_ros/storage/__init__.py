"""Storage layer: the bag file formats (MCAP, rosbag2 sqlite3, ROS 1) read and written."""
