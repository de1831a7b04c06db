"""Interoperability side: FMI compliance checks, SSP export, libcosim as a second master."""
