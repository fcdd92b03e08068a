"""The DeciZebro's interfaces as its companion computer sees them (``interfaces``): the UWB radio with data, the
utility sensor, the IMU and the legs, each a device of the robot reached as ``robot.device(name)``."""
