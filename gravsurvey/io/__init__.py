"""Input and output: log readers (MCAP, CSV) -> FlightRecord; deliverable writers."""
