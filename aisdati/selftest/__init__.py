"""The paper's synthetic protocol (Tables 1 and 2): the families and their reference source,
the settings and presets, the protocol itself, the paper's numbers, the summary statistics,
the outputs and figures."""
