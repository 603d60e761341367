"""Design of experiments (thesis chapter 5) and the designed runs of the pantograph rig."""
