"""glTF 2.0: doll and animation out (``write``), skinned characters in (``read``, ``rig``)."""
