"""The oscillator: parameters, exact flow, impacts, the controller's law, the compiled kernel.

Layer 1 of 7 (the bottom; docs/architecture.md). What a forced, damped mass against a
rigid wall does between two instants, exactly: :mod:`.params` (one immutable, validated
parameter object; d*, tau*, X** derived), :mod:`.flow` (the closed-form flow in deviation
coordinates), :mod:`.impact` (certified impact detection, the impact law, saltation,
chattering and sticking), :mod:`.control` (the discrete correction of Eq. 28 and its
gains) and :mod:`.kernel` (the same flow and search compiled by numba, bit-identical).

May import: :mod:`grazing_control.support` only. Never rclpy.
"""
