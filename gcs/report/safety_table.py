"""The comparison report's table of honest safety and tracking metrics (true states, the
safety verdict) and its legend (docs/metrics.md)."""

from __future__ import annotations

from gcs.report.shared import LABELS, failed_rows, md_legend
from gcs.report.shared import fmt as _f


def safety_table(metrics: dict[str, dict], failed: dict[str, str] | None = None) -> str:
    """Markdown table of the honest safety and tracking metrics (docs/metrics.md); the
    methods of ``failed`` (method -> why its run failed) as rows marked FAILED."""
    out = (
        "| Method | Verdict (events) | True h_min (m²) | Own h_min (m²) | Steps h<0 | "
        "Pair-steps h<0 | Min dist formation / mission (m) | Clipped agent-steps | "
        "Track RMS / max (m) | Time err > 0.1 m (s) |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n"
    )
    for m, met in metrics.items():
        ph = met.get("min_distance_by_phase_m") or {}
        out += (
            f"| {LABELS.get(m, m)} | {met.get('safety_verdict', '–')} "
            f"({_f(met.get('safety_alarm_count'))}) | {_f(met.get('h_min'), 3)} | "
            f"{_f(met.get('own_h_min'), 3)} | "
            f"{_f(met.get('barrier_violation_steps'))} | "
            f"{_f(met.get('barrier_violation_pair_steps'))} | "
            f"{_f(ph.get('formation'), 3)} / {_f(ph.get('mission'), 3)} | "
            f"{_f(met.get('input_clipped_steps'))} | {_f(met.get('tracking_rms_m'), 3)} / "
            f"{_f(met.get('tracking_max_m'), 3)} | "
            f"{_f(met.get('tracking_time_above_0p1_s'), 2)} |\n"
        )
    return out + failed_rows(failed, 10)


def safety_legend(d_safe: float, tau: float, deadline_s: float) -> str:
    """Definition and unit of every column of :func:`safety_table`."""
    return md_legend(
        [
            ("Method", "as above."),
            (
                "Verdict (events)",
                "`safety_verdict`: safe (no event), alarm (the truth held but an agent's own "
                "barrier went below 0 or it raised an alarm) or unsafe (the true barrier went "
                "below 0, a contact or a ground strike); in brackets the number of events "
                "(`safety_alarms` in metrics.json, docs/metrics.md).",
            ),
            (
                "True h_min (m²)",
                f"smallest barrier h_ij = ‖Δp‖² + 2τ ΔvᵀΔp − D² (τ = {tau:g} s, "
                f"D = {d_safe:g} m) over every pair of vehicles and every control step, from "
                "the simulator's true positions and velocities; negative: the safe set was left.",
            ),
            (
                "Own h_min (m²)",
                "the smallest barrier a follower computed from its own estimates (what its "
                "filter kept); negative: its margin was used up.",
            ),
            ("Steps h<0", "control steps at which some pair has a negative true barrier."),
            ("Pair-steps h<0", "(pair, control step) samples with a negative true barrier."),
            (
                "Min dist formation / mission (m)",
                f"smallest pair distance before / from t = {deadline_s:g} s "
                "(`run.formation_deadline_s`); '–' for a phase the run does not reach.",
            ),
            (
                "Clipped agent-steps",
                "agent-steps where the attitude/thrust limits changed the commanded u; '–' "
                "when the recorded statuses do not carry it.",
            ),
            (
                "Track RMS / max (m)",
                f"RMS and maximum of the followers' distance to their desired vertices over the "
                f"fixed window [{deadline_s:g} s, end], whatever happens in it; '–' when the run "
                "ends before the window starts.",
            ),
            (
                "Time err > 0.1 m (s)",
                "time in that window during which some follower is more than 0.1 m off.",
            ),
        ]
    )
