#!/usr/bin/env python3
"""A rig driver to fill in: your DAQ's calls in the four marked places.

Copy this file, replace the fake DAQ (``FakeDaq``: a sinusoidal motion, no impacts, a
clock of its own) by your hardware's calls, and run it beside the controller:

    python3 template_driver.py --ros-args -p sensor_rate:=2000.0 -p frequency:=13.34

As it is, it runs with the fake DAQ, so that the contract can be tried (and is tested:
tests/test_rig_drivers.py runs this file over Fast DDS). Everything of the driver
contract (docs/driver_contract.md) that is not your hardware is done by
:class:`grazing_control.ros.rig_driver.RigDriver`: the topics, the stamps, the clock
pairs, the actuation engine (deadlines, predictions, the count of what acted, rig/applied).

Parameters (besides RigDriver's poll_period, clock_rate, actuator_latency, on_miss):
``sensor_rate`` (Hz, 2000), ``sensor_latency`` (s, 0.0005), ``frequency`` (the forcing,
Hz, 13.34), ``amplitude`` (the fake motion, m, 1e-4).
"""

from __future__ import annotations

import math
import time

from grazing_control.ros.common import float_descriptor, run_node
from grazing_control.ros.rig_driver import RigDriver

#: An arbitrary origin of the fake DAQ's clock (s): a rig clock is not ROS time.
RIG_EPOCH = 1000.0


class FakeDaq:
    """Stands in for the hardware: replace each method by your DAQ's call."""

    def __init__(self, rate: float, latency: float, frequency: float, amplitude: float):
        self.rate, self.latency = rate, latency
        self.frequency, self.amplitude = frequency, amplitude
        self.t0 = time.monotonic() - RIG_EPOCH
        self.next_index = math.ceil(self.clock() * rate)
        self.pulses = []

    def clock(self) -> float:
        """The DAQ's sample clock (s)."""
        return time.monotonic() - self.t0

    def motion(self, t: float) -> tuple:
        """The fake rig: x = A cos(2 pi f t), no impacts."""
        w = 2.0 * math.pi * self.frequency
        return self.amplitude * math.cos(w * t), -self.amplitude * w * math.sin(w * t)

    def read_block(self) -> list:
        """The samples converted by now (a sample is available ``latency`` after it was
        taken)."""
        last = math.floor((self.clock() - self.latency) * self.rate)
        out = []
        for j in range(self.next_index, last + 1):
            t = j / self.rate
            out.append((t, *self.motion(t)))
        self.next_index = max(self.next_index, last + 1)
        return out

    def schedule_output(self, start: float, width: float, volts: float) -> None:
        """A timed analog output (the amplifier of the voice coil)."""
        self.pulses.append((start, width, volts))


class TemplateDriver(RigDriver):
    """The driver of one rig (fill in the four hooks)."""

    def __init__(self):
        super().__init__("template_driver")
        rate = self.declare_parameter("sensor_rate", 2000.0, float_descriptor(
            "sensor samples per second", 1.0, 1e6, read_only=True)).value
        latency = self.declare_parameter("sensor_latency", 5e-4, float_descriptor(
            "seconds from a sample to its availability", 0.0, 1.0, read_only=True)).value
        self.frequency = self.declare_parameter("frequency", 13.34, float_descriptor(
            "forcing frequency (Hz)", 1e-3, 1e4, read_only=True)).value
        amplitude = self.declare_parameter("amplitude", 1e-4, float_descriptor(
            "the fake motion's amplitude (m)", 0.0, 1.0, read_only=True)).value
        self.force_constant = 1.0        # N per volt of your amplifier and coil
        self.daq = FakeDaq(rate, latency, self.frequency, amplitude)   # 1. open your DAQ
        self.start()

    def rig_time(self) -> float:
        return self.daq.clock()                                       # 2. its clock

    def read_sensor(self):
        return self.daq.read_block()                                  # 3. its samples

    def phase_reference(self):
        t = self.daq.clock()             # the fake forcing's phase is 2 pi f t
        return t, self.frequency, (2.0 * math.pi * self.frequency * t) % (2.0 * math.pi)

    def write_pulse(self, start: float, width: float, force: float) -> None:
        self.daq.schedule_output(start, width, force / self.force_constant)   # 4. output


def main(args=None) -> int:
    return run_node(TemplateDriver, args, "template_driver")


if __name__ == "__main__":
    raise SystemExit(main())
