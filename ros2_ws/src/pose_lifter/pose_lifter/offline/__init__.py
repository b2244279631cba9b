"""Recorded data: bag I/O, the offline lift of one bag or a collection, export and the demo."""
