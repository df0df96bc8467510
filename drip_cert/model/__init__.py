"""The model layer: expressions, blocks, the MLP value object, :class:`System` and its numeric view.

Nothing here imports analysis, learning, bounds or simulation.
"""
