"""Events: which vessel did what, from when to when, where, and why it stands out.

Kinds (`kinds`) are defined once; the model-free finders read one vessel's reports
(`reports.VesselReports`): reported against observed motion (`motion`) and behaviour
(`behaviour`); `find` runs them all and places what they found. Events from a learned model
(off-traffic) are made where tracks are judged (`aisdati.detection`)."""
