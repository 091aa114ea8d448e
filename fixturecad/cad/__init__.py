"""The CAD room: the only modules (with the templates' ``body()``) that import cadquery or OCP.

``solid`` assembles a template's fixture solid, ``brep`` reads its faces back
and matches them to the features, ``mesh`` tessellates it, and ``export``
writes every file the kernel makes, picking the format from the file name.
"""
