"""Bring-up of the IRB 1600 node graph, the main job (thesis pipeline) and its report."""
