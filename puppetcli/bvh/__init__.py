"""BVH skeletons and motions: the types and their maths (``model``), reading, writing, and
rigs made from a BVH skeleton.
"""
