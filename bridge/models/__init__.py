"""Parts many robots share, as the world simulates them: a differential drive, sonars, a light sensor, a top marker
for an overhead camera.

A robot plugin lists the ones it has in its profile (``RobotProfile.parts``); a part only one robot has lives in that
robot's folder (a conveyor, say). See ``bridge.core.parts`` for the hooks.
"""
