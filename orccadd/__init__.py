"""orccadd: a hardware-in-the-loop robot controller daemon after ORCCAD.

Robot-Tasks (modules wired in a reactive shell) run periodically on Physical Resources;
Robot-Procedures compile to verified automata. See README.md and docs/.
"""

__version__ = "0.1.0"
