"""The sim-to-real gap diagnosis: where the gap lies, which effect causes it, how far it shrinks."""
