"""The DeciZebro's robot code on its main computer (a Raspberry Pi Zero W): its locomotion layer over the legs' I2C
bus (``locomotion``)."""
