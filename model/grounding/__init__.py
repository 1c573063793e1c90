"""The shared scene encoder, the grounding-head interface and its two heads, assembled from the
stages (``nets``, ``head``, ``referent``) below them.
"""
