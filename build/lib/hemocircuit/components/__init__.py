"""The hemocircuit component library (imports as ``hemocircuit.components``).

One module (or sub-package) per element type.  Every :class:`hemocircuit.component.Component`
subclass with a ``type_name`` found here is available in netlists; nothing else needs editing.
"""
