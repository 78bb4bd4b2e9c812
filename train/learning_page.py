"""The learning page's sections on how each seed's policy moves and which acceptance bars it meets (``train.curves``).

Both are written from the numbers of ``scores.json`` (its ``final`` and ``controllers``), so a page can be written
again from them:

- how it moves (``train.motion``): one column per seed, the IQM across seeds with its 95% stratified-bootstrap
  interval, and one per controller, over all the held-out episodes; on the push task a second table with no push
  at all (the same seeds, ``push_force`` (0, 0));
- the bars (``train.bars``): one column per seed, each bar passed or failed with the number measured (and, for a
  comparison with a controller, the controller's number on the episodes both survive), and how many seeds of the
  sweep meet every bar.
"""

from __future__ import annotations

from train.bars import BarCheck, bars_for, bars_table, meets_every_bar
from train.motion import Estimate, motion_table

__all__ = ["motion_section", "bars_section", "checks_from_scores"]


def _estimate(iqm: dict[str, list[float]], unit: str) -> Estimate:
    """The IQM column of a motion table from ``{measure: (iqm, low, high)}``."""
    return Estimate(*({key: value[k] for key, value in iqm.items()} | {"normal_force_unit": unit} for k in range(3)))


def _motion_table(final: dict, controllers: dict[str, dict], labels: dict[str, str], case: str) -> str:
    """The motion table of ``case``: ``"all"`` (the held-out episodes) or ``"no_push"`` (the same seeds without
    pushes, headed by each one's survival there)."""
    where = (lambda scores: scores) if case == "all" else (lambda scores: scores["no_push"])
    policies = {label: where(final["per_seed"][seed]) for seed, label in labels.items()}
    others = {f"{name} (controller)": where(scores) for name, scores in controllers.items() if case == "all" or "no_push" in scores}
    columns: dict = {label: summary["motion"] for label, summary in policies.items()}
    survival = [f"{100 * summary['survival_rate']:.0f}%" for summary in policies.values()]
    if case in final.get("motion_iqm", {}):
        unit = next(iter(columns.values())).get("normal_force_unit", "m g")
        columns[f"PPO, IQM of {len(labels)} seeds [95% CI]"] = _estimate(final["motion_iqm"][case], unit)
        survival.append("")
    columns.update({label: summary["motion"] for label, summary in others.items()})
    survival += [f"{100 * summary['survival_rate']:.0f}%" for summary in others.values()]
    return motion_table(columns, [("survival rate", survival)] if case == "no_push" else [])


def motion_section(final: dict, controllers: dict[str, dict], labels: dict[str, str]) -> list[str]:
    """The page's lines on how each seed moves (``labels``: each seed's column heading, by the seed as a string)
    beside ``controllers`` (each one's kept scores, by name); none when the scores hold no motion measures."""
    if not all("motion" in final["per_seed"][seed] for seed in labels):
        return []
    lines = ["How each seed's selected policy moves on the held-out episodes (`train.motion`), beside the controllers on the "
             "same episodes; the IQM across seeds with its 95% stratified-bootstrap interval:", "",
             _motion_table(final, controllers, labels, "all"), "", "![how each seed moves](motion.png)", ""]  # fmt: skip
    if all("no_push" in final["per_seed"][seed] for seed in labels):
        lines += ["With no push at all (the same seeds, `push_force` (0, 0)):", "", _motion_table(final, controllers, labels, "no_push"), ""]
    return lines


def checks_from_scores(records: list[dict], env_id: str, env_kwargs: dict) -> list[BarCheck]:
    """The bar checks of ``scores.json`` (``BarCheck.as_dict``'s records) again, each with its bar (``train.bars``,
    found by its description) so that its numbers are written as the bar writes them."""
    bars = {bar.description: bar for bar in bars_for(env_id, env_kwargs)}
    return [BarCheck(**record, bar=bars.get(record["description"])) for record in records]


def bars_section(final: dict, labels: dict[str, str], env_id: str, env_kwargs: dict) -> list[str]:
    """The page's lines on the bars each seed meets, and how many seeds meet every one; none for a task without bars."""
    if not all(final["per_seed"][seed].get("bars") for seed in labels):
        return []
    checks = {label: checks_from_scores(final["per_seed"][seed]["bars"], env_id, env_kwargs) for seed, label in labels.items()}
    meeting = sum(meets_every_bar(c) for c in checks.values())
    return ["Bars (`train.bars`): each seed's selected policy on the held-out episodes; a comparison with a controller on the "
            "episodes both survive (the bar is the controller's number there), the return on all of them:", "",
            bars_table(checks), "", f"**{meeting} of {len(labels)} seeds meet every bar.**", ""]  # fmt: skip
