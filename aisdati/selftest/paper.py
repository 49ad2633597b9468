"""The paper's self-test numbers (Tables 1 and 2), printed beside ours."""

from __future__ import annotations

PAPER_FAMILIES = ("fixedstart", "ushaped", "circles", "ribbons")
"""The four synthetic families of the paper's Table 1."""

PAPER_TABLE1 = {
    "dati": {"fixedstart": 0.065, "ushaped": 0.231, "circles": 0.058, "ribbons": 0.033},
    "bc": {"fixedstart": 0.124, "ushaped": 0.365, "circles": 0.106, "ribbons": 0.113},
    "bc-paper": {"fixedstart": 0.124, "ushaped": 0.365, "circles": 0.106, "ribbons": 0.113},
    "ddpg-ti": {"fixedstart": 0.489, "ushaped": 2.138, "circles": 0.972, "ribbons": 0.172},
}
"""Table 1 of the paper: best normalised smoothed DTW over 10 seeds x 10 references."""

PAPER_ABLATION = {
    "dati": (0.058, 0.074),
    "dati-no-time-embedding": (1.829, 1.976),
    "dati-no-reward-input": (0.305, 0.451),
}
"""Table 2 of the paper (Circles): top-1 and top-2 normalised smoothed DTW."""


def paper_numbers(method: str, family: str) -> tuple[float | None, float | None]:
    """The paper's (top-1, top-2) for a method and family, where it reports them."""
    top2 = PAPER_ABLATION.get(method) if family == "circles" else None
    top1 = PAPER_TABLE1.get(method, {}).get(family)
    if top1 is None and top2 is not None:
        top1 = top2[0]
    return top1, (top2[1] if top2 else None)
