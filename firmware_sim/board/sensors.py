"""Electrical transfer functions of the eSwarBot's analog sensors (physical quantity -> pin volts).

The world supplies physical truth (range in metres, illuminance in lux, battery volts, with the
sensors' physical noise); these functions model the sensor electronics in front of the ADC, and their
inverses are what the firmware computes from ADC counts.
"""

from __future__ import annotations

VCC = 5.0

# Analog ultrasonic ranger (MaxBotix-style scaling, Vcc/512 per inch).
SONAR_VOLTS_PER_M = VCC / 512 / 0.0254


def sonar_volts(range_m: float) -> float:
    return range_m * SONAR_VOLTS_PER_M


def sonar_mm_from_adc(counts: int, adc_max: int = 1023, vref: float = VCC) -> int:
    return round(counts * vref / (adc_max + 1) / SONAR_VOLTS_PER_M * 1000)


# LDR (GL55-class, R10 = 20 kOhm, gamma = 0.7) from Vcc to the pin, 10 kOhm from the pin to ground.
LDR_R10_OHM = 20_000.0
LDR_GAMMA = 0.7
LDR_FIXED_OHM = 10_000.0


def ldr_volts(lux: float) -> float:
    lux = max(lux, 1e-3)
    r_ldr = LDR_R10_OHM * (lux / 10.0) ** (-LDR_GAMMA)
    return VCC * LDR_FIXED_OHM / (LDR_FIXED_OHM + r_ldr)


# Battery through a 1:2 resistor divider.
BATTERY_DIVIDER = 0.5


def battery_volts_at_pin(v_batt: float) -> float:
    return v_batt * BATTERY_DIVIDER


def battery_mv_from_adc(counts: int, adc_max: int = 1023, vref: float = VCC) -> int:
    return round(counts * vref / (adc_max + 1) / BATTERY_DIVIDER * 1000)
