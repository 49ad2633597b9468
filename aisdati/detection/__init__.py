"""`aisdati detect`: which model judges each test track, the scores and flags (run), hand
labels and incident lists (labels), and what is written: tables, GeoJSON, maps, report
(outputs, maps, webmap)."""
