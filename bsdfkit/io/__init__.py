"""Readers and writers. No physics here beyond unit bookkeeping."""
