"""The DeciZebro's own firmware: its six ZebroBus leg modules (ATxmega32A4U class), I2C slaves of the main computer."""
