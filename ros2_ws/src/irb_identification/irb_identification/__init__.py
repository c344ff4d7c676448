"""MCAP recording, replay, friction identification and the model-discrepancy workflow for the IRB 1600."""
