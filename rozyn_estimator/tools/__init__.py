"""The command-line tools (``rozyn``): trial, compare, study, replay, demo, bench.

Tools may use the simulator (``sim_node``) as well as the estimator; the command registry
(:mod:`.cli`) imports a tool's module only when its command runs.
"""
