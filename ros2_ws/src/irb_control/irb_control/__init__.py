"""PD+ controller with friction compensation, simulator and axis-computer bridge (IRB 1600)."""
