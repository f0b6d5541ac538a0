"""Training of PONI's potential network: partial maps drawn from full house maps (``samples``), the
choices of a prior-free agent's walks (``walks``) and the ``l3mvn poni`` command (``train``)."""
