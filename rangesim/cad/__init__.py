"""CAD: parametric parts, part trees, B-spline surfaces, analytic features, surface sampling.

Knows parts, not sensors.
"""
