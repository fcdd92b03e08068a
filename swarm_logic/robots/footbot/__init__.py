"""The foot-bot's interfaces as its controller sees them (``interfaces``): the range-and-bearing board, the
proximity, light and motor-ground sensors, the differential-steering wheels and the LEDs, each a device of the
robot reached as ``robot.device(name)``."""
