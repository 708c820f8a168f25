"""The viewer's one-slot mailbox: a burst of requests while an answer is being computed leaves
only the latest to answer.
"""

import threading

from stmpl.viewer.mailbox import Latest


def test_only_the_latest_request_is_answered():
    gate, answered = threading.Event(), []
    box = Latest(lambda r: (gate.wait(5), r)[1], lambda r, result: answered.append(result))
    box.put(0)  # taken at once, held at the gate
    while box.answered == 0 and not box._busy:
        pass
    for r in range(1, 20):  # a drag's burst while 0 is being answered
        box.put(r)
    gate.set()
    assert box.idle(5)
    assert answered == [0, 19] and box.dropped == 18 and box.answered == 2
    box.close()


def test_an_answer_that_raises_is_handed_over_and_the_box_goes_on():
    out = []
    box = Latest(lambda r: 1 / r, lambda r, result: out.append(result))
    box.put(0)
    assert box.idle(5)
    box.put(4)
    assert box.idle(5)
    assert isinstance(out[0], ZeroDivisionError) and "ZeroDivisionError" in out[0].trace
    assert out[1] == 0.25
    box.close()
