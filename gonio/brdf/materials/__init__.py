"""Where BRDFs come from: the synthetic training library, the shipped measured set, the user's
imported library and the readers of foreign files (MERL ``.binary``, RGL ``.bsdf``)."""
