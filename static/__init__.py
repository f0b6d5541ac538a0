"""The report page's assets (CSS, JS), shipped as package data of ``l3mvn_studio.static`` and read
with importlib.resources, so an installed wheel and an editable checkout find them alike."""
