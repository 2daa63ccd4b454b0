"""The browser viewer (viser) of every file manifoldgen writes: ``manifoldgen view FILE``.

``source`` reads a file into what it shows, ``meshes`` builds the triangle meshes placed by
pinocchio, ``scene`` puts them in a viser scene with its controls, ``server`` serves it, ``export``
writes it as one offline HTML page, and ``browser`` drives headless Chromium to look at the result.
"""
