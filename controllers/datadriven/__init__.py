"""Data-driven family (seed 001): FFDL-MFAC, FFDL-ISMC, FFDL-ISMPC and GPC for the EMU."""
