"""The networks of TPCNet: each sensor's pillar encoder (``pillars``) and backbone
(``backbone``), the LiDAR-radar fusion (``fusion``: one module per kind), the text encoders
(``text``, with ``numerals``: the values of numbers in a prompt), the text fusion of the paper's
path (``dggf``), the SECOND-FPN (``fpn``), the BEV grids (``grid``) and the scene encoder
assembling them (``scene_encoder``)."""
