"""controller_node's /diagnostics task: what it answered and refused, whether the
control is on, the rig side's clock, the model watch's estimates and verdict, the capture
and the re-identification (docs/nodes.md, "Diagnostics")."""

from __future__ import annotations

import math

from grazing_control.dynamics.design.capture import CAPTURE_PATIENCE

from .diagnostics import ERROR, OK, WARN
from .model_watch import WATCH_FIELDS, describe_verdict, watch_row, watch_status


def diagnose(node, stat):
    """The controller's /diagnostics task: answers, whether the control is on, and
    what it refused; WARN when a sample went unanswered (stale, malformed, non-finite)
    since the last message, or when it has not answered for a whole period while
    it had before (the simulator gone, or the controller starved). Under
    use_sim_time a period in which the simulation time stood (the scene over, or
    not started) expected no sample: no WARN for it (issue 27 §2)."""
    refused = node.malformed.count + node.stale.count + node.nonfinite.count
    last_answered, last_refused, last_clock = node.diag_last
    clock = node.get_clock()
    now = clock.now().nanoseconds if clock.ros_time_is_active else None
    node.diag_last = (node.answered, refused, now)
    standing = now is not None and now == last_clock
    stat.summary(OK, "controlling" if node.law.enabled else "answering (control off)")
    stat.add("answered", node.answered)
    stat.add("control on", str(node.law.enabled).lower())
    stat.add("enable_after", node.law.enable_after)
    stat.add("malformed", node.malformed.count)
    stat.add("stale", node.stale.count)
    stat.add("nonfinite", node.nonfinite.count)
    stat.add("out_of_order", node.law.out_of_order)
    if node.rig_side is not None:
        node.rig_side.diagnose(stat)
    if node.watching:
        diagnose_watch(node, stat)
    if node.capture is not None:
        diagnose_capture(node.capture, stat)
    if node.reid is not None:
        node.reid.diagnose(stat)
    if refused > last_refused:
        stat.merge_summary(WARN, f"{refused - last_refused} samples not answered "
                                 "(malformed, stale or non-finite)")
    if standing:
        stat.add("simulation time", "standing")
    elif last_answered and node.answered == last_answered:
        stat.merge_summary(WARN, "no sample answered in the last period")
    return stat

def diagnose_capture(rule, stat) -> None:
    """The capture rule: where it switched on, or while it holds back the closest
    approach of the estimate; WARN once it has held CAPTURE_PATIENCE sections without
    the estimate coming within its radius (docs/theory_capture.md)."""
    stat.add("captured at section", "not yet" if rule.on_at is None else rule.on_at)
    if rule.on_at is None and rule.held:
        stat.add("capture closest approach", f"{rule.closest:.4g} (radius {rule.radius:.4g},"
                                             f" {rule.held} sections held)")
        if rule.held >= CAPTURE_PATIENCE:
            stat.merge_summary(WARN, f"not captured: the estimate came no closer than "
                                     f"{rule.closest:.4g} to the orbit in {rule.held} "
                                     f"sections (radius {rule.radius:.4g})")


def diagnose_watch(node, stat) -> None:
    """The augmented filter's estimates and the consistency verdict: ERROR while the
    latest verdict is a mismatch (naming the failing tests, statistic vs bound), WARN
    when one came since the last message but the latest is consistent."""
    row = dict(zip(WATCH_FIELDS, watch_row(node.stream, node.verdict)))
    for name in ("bias", "bias_se", "delta_d", "delta_d_se"):
        if math.isfinite(row[name]):
            stat.add(name, f"{row[name]:.6g}")
    if node.monitor is None:
        return
    stat.add("mismatch sections", node.mismatches)
    if node.first_mismatch is not None:
        stat.add("first mismatch", node.first_mismatch)
    v = node.verdict
    if v is not None:
        stat.add("consistency", describe_verdict(v))
        stat.add("nis", f"{v.statistic:.6g} (bound {v.bound:.6g}, {v.dof} dof)")
        if v.mean_dof:
            stat.add("mean", f"{v.mean_statistic:.6g} (bound {v.mean_bound:.6g}, "
                             f"{v.mean_dof} dof)")
    new, node.diag_mismatches = node.mismatches - node.diag_mismatches, node.mismatches
    level, message = watch_status(v, new)
    if level is not None:
        stat.merge_summary(ERROR if level == "error" else WARN, message)
