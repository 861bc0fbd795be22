"""``cmmwb calibrate``: hyper-parameters of the six factors estimated from the machine's recordings."""
