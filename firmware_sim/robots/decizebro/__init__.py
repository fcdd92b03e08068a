"""The DeciZebro's own firmware: its six ZebroBus leg modules (ATxmega32A4U class), I2C slaves of the main computer;
its DWM1001 UWB radio with data (``uwb_radio``) and its BNO055 IMU (``imu``), each on a serial line to it."""
