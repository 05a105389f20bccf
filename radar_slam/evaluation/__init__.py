"""Evaluation against ground truth: trajectory metrics, loop judging, false-loop injection.

The library core (raplace, odometry, loops, graph, datasets, sim) never imports this package.
"""
