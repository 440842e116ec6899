"""Rendering: cameras, environment maps, the simulators a scene's effects call for, and the Mitsuba 3 adapter."""
