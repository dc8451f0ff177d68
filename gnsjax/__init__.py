"""gnsjax: learned simulation of granular avalanches (graph network simulator).

``gnsjax.render`` draws trajectories; the learned simulator itself lands in
later modules (see DESIGN.md).
"""
