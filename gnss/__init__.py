"""GNSS raw processing: RINEX, ephemeris, SPP, double differences, cycle slips, LAMBDA, RTK."""
