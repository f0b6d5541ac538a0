"""The run side: puts a world and an agent together and watches them. Policies by name
(``registry``), the navigation loop (``session``), warm floors (``runner``), step events, rerun
recordings, evaluation jobs and their result files, and the ``l3mvn`` command line.
"""
