"""An ATmega328P-class board as the firmware sees it: millis(), a 10-bit ADC, PWM and digital pins,
encoder interrupt counters, an RGB LED strip and a CAN controller.

The host process sets the electrical inputs (pin voltages, encoder counts, the clock) before each
``loop()`` and reads the outputs (PWM duties, direction pins, LED colour, CAN frames) after it.
Nothing here reads the wall clock: ``millis()`` is the session's simulated time.
"""

from __future__ import annotations

from typing import Protocol

from firmware_sim.board.can_controller import CanController, Frame

HIGH, LOW = 1, 0


class Board:
    """Pins and peripherals of one Arduino-class board."""

    ADC_BITS = 10
    ADC_MAX = (1 << ADC_BITS) - 1
    VREF = 5.0

    def __init__(self, can_rx_depth: int = 8) -> None:
        self.time_us = 0
        self.analog_volts: dict[str, float] = {}
        self.pwm: dict[str, int] = {}
        self.digital: dict[str, int] = {}
        self.encoder_counts = [0, 0]
        self.led_rgb = (0, 0, 0)
        self.stepper_steps = 0  # steps a stepper driver was pulsed (a conveyor belt), one direction
        self.pwm_inputs: dict[str, tuple[float, float]] = {}  # pin -> (duty 0..1, frequency Hz) of a PWM source
        # a motion-capture receiver's latest pose (x m, y m, yaw rad, world frame), when one is fitted
        self.external_pose: tuple[float, float, float] | None = None
        self.can = CanController(rx_depth=can_rx_depth)

    def feed_can(self, items: list) -> None:
        """What the robot's bus delivered to this node, as the firmware host hands it: ``["can0", id, data, extended,
        t_ns]`` a frame from another node, ``["can0_state", state, tec, rec]`` a change of its controller's
        fault-confinement state (its EFLG register); error frames (a sixth field) only moved the counters."""
        for item in items:
            if item[0] == "can0_state":
                self.can.set_error_state(item[1], item[2], item[3])
            elif item[0] == "can0" and len(item) == 5:
                _bus, arb_id, data, ext, ts = item
                self.can.on_bus_frame(Frame(arb_id, data, ts // 1000, ext))

    # -- Arduino API -------------------------------------------------------------------------------
    def millis(self) -> int:
        return self.time_us // 1000

    def micros(self) -> int:
        return self.time_us

    def analog_read(self, pin: str) -> int:
        """10-bit conversion of the pin voltage, clamped to 0..VREF (as the ADC saturates)."""
        v = self.analog_volts.get(pin, 0.0)
        v = 0.0 if v < 0 else min(v, self.VREF)
        return min(self.ADC_MAX, int(v / self.VREF * (self.ADC_MAX + 1)))

    def analog_write(self, pin: str, duty: int) -> None:
        self.pwm[pin] = max(0, min(255, int(duty)))

    def digital_write(self, pin: str, level: int) -> None:
        self.digital[pin] = HIGH if level else LOW

    def digital_read(self, pin: str) -> int:
        if pin in self.pwm_inputs:  # a PWM source held at 100 % duty reads high, at 0 % low
            duty, _ = self.pwm_inputs[pin]
            return HIGH if duty >= 1.0 else LOW if duty <= 0.0 else self.digital.get(pin, LOW)
        return self.digital.get(pin, LOW)

    def pulse_in(self, pin: str, timeout_us: int = 1_000_000) -> int:
        """``pulseIn(pin, HIGH)``: length in us of a high pulse on ``pin``, 0 when none comes (a flat line).

        The timer counts in 4 us steps on a 16 MHz board, so the result is a multiple of 4.
        """
        duty, hz = self.pwm_inputs.get(pin, (0.0, 0.0))
        if hz <= 0 or duty <= 0.0 or duty >= 1.0 or 1e6 / hz > timeout_us:
            return 0
        return int(duty * 1e6 / hz) // 4 * 4

    def encoder(self, channel: int) -> int:
        """Signed pulse count kept by the encoder interrupt routine of wheel ``channel``."""
        return self.encoder_counts[channel]

    def stepper_pulses(self, n: int) -> None:
        """Pulse the stepper driver's STEP pin ``n`` times (the belt advances one step each)."""
        self.stepper_steps += max(0, int(n))

    def led_strip(self, r: int, g: int, b: int) -> None:
        self.led_rgb = (max(0, min(255, r)), max(0, min(255, g)), max(0, min(255, b)))


class Sketch(Protocol):
    """What an Arduino sketch provides; the runtime calls ``setup()`` once, then ``loop()`` at its rate."""

    loop_period_us: int

    def setup(self) -> None: ...

    def loop(self) -> None: ...


def next_loop_ns(nominal_ns: int, period_ns: int, t_ns: int) -> int:
    """A fixed-rate loop's next nominal time after ``t_ns`` (millis()-based, as on the board): the world rounds it up
    to a quantum boundary, so when the quantum does not divide the period the loop jitters but keeps its rate."""
    nominal = nominal_ns + period_ns
    while nominal <= t_ns:
        nominal += period_ns
    return nominal
