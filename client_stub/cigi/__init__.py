"""The CIGI 3.3 host: soldiers from a Jack/TTES server sent to a CIGI image generator over UDP."""
