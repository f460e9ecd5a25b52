"""Moving objects carried from sweep to sweep: their motions over time, their evidence in
a pair of sweeps, and the tracks that hold them (used by
:class:`mmreg.SequenceRegistration`)."""
