"""Training of PONI's potential network: partial maps drawn from full house maps (``samples``) and
the ``l3mvn poni`` command (``train``)."""
