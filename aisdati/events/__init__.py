"""Events: which vessel did what, from when to when, where, and why it stands out.

One place for the event model: the kinds (`kinds`: each one's class, alert or activity, its
longest and its definition), the record every event is written as (`record`), the reports one
vessel's finders read (`reports`), the model-free finders (`motion`: reported against observed
motion; `behaviour`: drift, sudden speed change, loitering, gaps, ashore) run and placed by
`find`, the alert budget (`budget`, calibrated on a model's training period by `calibrate`),
and the rules detect, evaluate and watch all judge by (`rules`). To add a kind: its line in
`kinds`, its finder in `find.FINDERS`, its row in docs/detectors.md. Learned events
(off-traffic, unseen-route) are made where tracks are judged (`aisdati.detection.events`),
through the same record."""
