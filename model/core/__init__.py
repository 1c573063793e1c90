"""Shared types of the model: the BEV grid, anchor points, labelled boxes, a scene's candidates, the
model's inputs and outputs.

The bottom layer of ``model``: it imports no other part of ``model``.
"""
