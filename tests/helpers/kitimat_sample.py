"""A small real sample of the Kitimat data (six vessels, the first week of July 2018: 3,575
reports, 32 tracks with `--roi none --min-points 20`), and the same rows in the Danish Maritime
Authority's CSV layout.

`python tests/helpers/kitimat_sample.py` writes the DMA fixture,
tests/data/DMA_2018_07_Kitimat_sample.csv.gz; the tests import `kitimat_rows` to rebuild the
MarineCadastre rows it was made from (and check that the fixture is what this script writes).
"""

from __future__ import annotations

import gzip
import io
from pathlib import Path

import pandas as pd

DATA = Path(__file__).resolve().parents[1] / "data"
KITIMAT = DATA / "AIS_2018_07-08_Kitimat.csv.gz"
DMA_SAMPLE = DATA / "DMA_2018_07_Kitimat_sample.csv.gz"
VESSELS = ("100000634", "100001938", "100001691", "100000507", "100000809", "100000796")
"""The six vessels with the most reports above 3 knots in the first week."""
BEFORE = "2018-07-08"
DMA_COLUMNS = [
    "# Timestamp",
    "Type of mobile",
    "MMSI",
    "Latitude",
    "Longitude",
    "Navigational status",
    "ROT",
    "SOG",
    "COG",
    "Heading",
    "IMO",
    "Callsign",
    "Name",
    "Ship type",
    "Cargo type",
    "Width",
    "Length",
    "Type of position fixing device",
    "Draught",
    "Destination",
    "ETA",
    "Data source type",
    "A",
    "B",
    "C",
    "D",
]


def kitimat_rows() -> pd.DataFrame:
    """The sample's rows as the Kitimat file writes them (all columns text, in file order)."""
    rows = pd.read_csv(KITIMAT, dtype=str, keep_default_na=False)
    keep = rows["MMSI"].isin(VESSELS) & (rows["BaseDateTime"] < BEFORE)
    return rows[keep].reset_index(drop=True)


def dma_layout(rows: pd.DataFrame) -> pd.DataFrame:
    """MarineCadastre rows in the DMA's columns, with the DMA's spellings: day-first times,
    'Class A', 'Unknown' for what is not known, a blank heading where AIS says 511."""
    n = len(rows)
    blank = [""] * n
    times = pd.to_datetime(rows["BaseDateTime"]).dt.strftime("%d/%m/%Y %H:%M:%S")
    columns = {
        "# Timestamp": times,
        "Type of mobile": "Class " + rows["TransceiverClass"],
        "MMSI": rows["MMSI"],
        "Latitude": rows["LAT"],
        "Longitude": rows["LON"],
        "Navigational status": ["Unknown value"] * n,
        "SOG": rows["SOG"],
        "COG": rows["COG"],
        "Heading": rows["Heading"].where(rows["Heading"] != "511", ""),
        "IMO": ["Unknown"] * n,
        "Callsign": ["Unknown"] * n,
        "Ship type": rows["VesselType"].where(rows["VesselType"] != "", "Undefined"),
        "Length": rows["Length"],
        "Type of position fixing device": ["Undefined"] * n,
        "Destination": ["Unknown"] * n,
        "Data source type": ["AIS"] * n,
    }
    return pd.DataFrame({c: columns.get(c, blank) for c in DMA_COLUMNS})


def write_dma_sample(path: Path) -> None:
    """The sample in the DMA layout, gzipped (reproducibly: no time in the gzip header)."""
    text = io.StringIO()
    dma_layout(kitimat_rows()).to_csv(text, index=False, lineterminator="\n")
    path.write_bytes(gzip.compress(text.getvalue().encode(), mtime=0))


def main() -> None:
    write_dma_sample(DMA_SAMPLE)
    print(f"wrote {DMA_SAMPLE} ({DMA_SAMPLE.stat().st_size:,} bytes)")


if __name__ == "__main__":
    main()
