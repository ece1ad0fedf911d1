"""The in-process bus lock every stage driver on one serial port or URL shares."""

from __future__ import annotations

import threading
import time

from gonio.drivers._ownership import bus_lock


def test_one_lock_per_endpoint_whichever_driver_asks() -> None:
    assert bus_lock("/dev/ttyUSB-test-a") is bus_lock("/dev/ttyUSB-test-a")
    assert bus_lock("/dev/ttyUSB-test-a") is not bus_lock("/dev/ttyUSB-test-b")


def test_transactions_on_one_bus_never_overlap() -> None:
    inside = 0
    most_inside = 0
    guard = threading.Lock()

    def transaction() -> None:
        nonlocal inside, most_inside
        with bus_lock("socket://127.0.0.1:9"):
            with guard:
                inside += 1
                most_inside = max(most_inside, inside)
            time.sleep(0.002)  # a reply's wire time; another thread would enter here
            with guard:
                inside -= 1

    threads = [threading.Thread(target=transaction) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert most_inside == 1
