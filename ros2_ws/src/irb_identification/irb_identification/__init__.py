"""MCAP recording, replay, friction identification and the model-discrepancy workflow."""
