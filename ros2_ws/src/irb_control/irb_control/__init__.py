"""PD+ controller with friction compensation, simulator and axis-computer bridge for the IRB 1600."""
