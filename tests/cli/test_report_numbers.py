"""A narrow interval reads apart in a report: its ends get the digits that separate them."""

from negstiff.report.numbers import fmt, fmt_interval


def test_a_narrow_interval_is_printed_with_the_digits_that_separate_its_ends():
    # a k3 posterior 90 % interval 7.7698e5 to 7.7704e5 N/m^3 (sd ~20 N/m^3): 4 figures print both as 7.770e+05
    assert fmt(776980.0) == fmt(777040.0) == "7.770e+05"
    lo, hi = fmt_interval(776980.0, 777040.0)
    assert lo != hi and (lo, hi) == ("7.7698e+05", "7.7704e+05")
    assert fmt_interval(1.0, 2.0) == ("1", "2")  # a wide one keeps the report's 4 figures
    assert fmt_interval(3.0, 3.0) == ("3", "3")
