"""`aisdati evaluate`: anomalies written into real held-out tracks (inject, dataset), the
detectors trained and scored on them (run), the only ROC / PR / F1 of aisdati (metrics), and what
is written (outputs, figures)."""
