"""Document 004 (Ozkaya 2011) scenario facts (locbook.scenarios.ozkaya): the thesis CRLB sweep against every
printed value."""


def test_thesis_crlb_sweep_reproduces_every_printed_value():
    from locbook.scenarios import ozkaya as oz
    printed = {1.0: 0.15, 3.0: 0.46, 5.2: 0.80, 7.0: 1.08, 9.0: 1.38, 11.0: 1.70}
    for sigma, value in printed.items():
        # the printed columns come from the thesis's formula with n = 2 and the mean over the 1 m cells: the
        # reading fitted to them (the defaults are the text's n = 2.3 and the RMS over the room)
        assert abs(oz.thesis_crlb_m("corners3", sigma, 2.0, "cells_mean") - value) <= 0.02
    assert abs(oz.thesis_crlb_m("corners4", 5.2, 2.0, "cells_mean") - 0.64) <= 0.02
    # the correct bound (1/d^4) is several times larger
    assert 3.0 < oz.correct_crlb_m("corners3", 5.2) < 4.0
