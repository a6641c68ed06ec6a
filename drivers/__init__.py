"""Bytes to typed samples: the protocol parsers (MAVLink, NMEA, DVL JSON, PD6), the log
readers (tlog, DataFlash, CSV, text captures, the service's recordings) and the live
transports (serial, UDP, TCP, pseudo-terminals). Only :mod:`onboard.core` below them."""
