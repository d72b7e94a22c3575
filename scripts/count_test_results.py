#!/usr/bin/env python3
"""Counts test cases in catkin's JUnit XML results and prints 'N passed, N failed, N skipped'.

Usage: count_test_results.py RESULTS_DIR
Exit status: 0 if at least one test ran and none failed, 1 otherwise.
A result file that is missing its test cases (a crashed gtest binary, or rostest's
'testcase did not produce result') counts as a failure.
"""
import pathlib
import sys
import xml.etree.ElementTree as ET


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    root = pathlib.Path(sys.argv[1])
    passed = failed = skipped = 0
    bad_files = []
    for f in sorted(root.rglob("*.xml")):
        try:
            tree = ET.parse(f)
        except ET.ParseError as e:
            failed += 1
            bad_files.append(f"{f}: unreadable XML ({e})")
            continue
        cases = tree.getroot().iter("testcase")
        for case in cases:
            broken = case.find("failure") is not None or case.find("error") is not None
            # rostest writes a wrapper case per .test file beside the tester's own cases: it
            # counts only when it fails (a tester that crashed leaves no cases of its own).
            if case.get("classname") == "rostest.runner.RosTest" and not broken:
                continue
            if broken:
                failed += 1
                node = case.find("failure")
                if node is None:
                    node = case.find("error")
                why = " ".join(((node.get("message") or "") + " " + (node.text or "")).split())
                bad_files.append(f"{f}: {case.get('classname')}.{case.get('name')} failed"
                                 + (f": {why[:400]}" if why else ""))
            elif case.find("skipped") is not None or case.get("status") == "notrun":
                skipped += 1
            else:
                passed += 1
    for line in bad_files:
        print(line, file=sys.stderr)
    print(f"{passed} passed, {failed} failed, {skipped} skipped")
    if passed + failed == 0:
        print("no test was executed", file=sys.stderr)
        return 1
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
