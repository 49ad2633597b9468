"""Draw docs/coastline_kitimat.png: the Kitimat sample's tracks over the offline coastline.

    aisdati ingest --input tests/data/AIS_2018_07-08_Kitimat.csv.gz --roi none \\
        --min-points 100 --out /tmp/kitmaps
    python scripts/coastline_kitimat.py /tmp/kitmaps docs/coastline_kitimat.png
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from aisdati.coastline import on_land
from aisdati.plots import draw_land, save, set_map_limits

BOX = (-129.95, 52.55, -128.49, 53.76)  # the sample's area: Douglas Channel to Hecate Strait
COLORS = {"up": "tab:red", "down": "tab:blue", "other": "0.35"}


def main(data_dir: Path, out: Path) -> None:
    points = pd.read_parquet(data_dir / "points.parquet", columns=["track_id", "lon", "lat"])
    clusters = pd.read_parquet(data_dir / "tracks.parquet", columns=["track_id", "cluster"])
    cluster = dict(zip(clusters["track_id"], clusters["cluster"], strict=True))
    land = on_land(points["lon"].to_numpy(), points["lat"].to_numpy())
    fig, ax = plt.subplots(figsize=(8, 9))
    for tid, g in points.groupby("track_id", sort=False):
        c = cluster.get(tid, "other")
        ax.plot(g["lon"], g["lat"], color=COLORS[c], lw=0.5 if c == "other" else 1.0, alpha=0.7)
    set_map_limits(ax, np.array(BOX[:2]), np.array(BOX[2:]))
    draw_land(ax)
    handles = [plt.Line2D([], [], color=v, lw=1.2, label=f"{k} tracks") for k, v in COLORS.items()]
    ax.legend(handles=handles, fontsize=8, loc="upper right")
    ax.set_title(
        f"Kitimat sample, Jul-Aug 2018: {points['track_id'].nunique()} tracks, "
        f"{len(points):,} reports ({land.mean():.2%} on land)"
    )
    save(fig, out)
    print(f"wrote {out}; {land.sum()} of {len(points)} reports fall on land")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
