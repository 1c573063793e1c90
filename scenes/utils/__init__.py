"""Utilities every room may use: durable writes, the LRU cache, the text policy, strict text-file
reading.

The bottom room of ``scenes``: it imports no other room.
"""
