"""Physics-exact flight simulator: trajectory, anomalous field, sensors, log writers."""
