"""Add up pytest JUnit XML files and print one closing line: 'total: N passed, N failed, N skipped'.

    python scripts/junit_total.py results/*.xml
    python scripts/junit_total.py --failure NAME MESSAGE > stage.xml   # a stage that could not run
"""

import sys
import xml.etree.ElementTree as ET


def failure_xml(name, message):
    """A JUnit file with one failed test: a stage that could not run counts as a failure."""
    suite = ET.Element("testsuite", name=name, tests="1", failures="1", errors="0", skipped="0")
    case = ET.SubElement(suite, "testcase", classname=name, name="stage")
    ET.SubElement(case, "failure", message=message).text = message
    return ET.tostring(suite, encoding="unicode")


def main(paths):
    passed = failed = skipped = 0
    for path in paths:
        root = ET.parse(path).getroot()
        suites = [root] if root.tag == "testsuite" else list(root.iter("testsuite"))
        for s in suites:
            tests = int(s.get("tests", 0))
            f = int(s.get("failures", 0)) + int(s.get("errors", 0))
            sk = int(s.get("skipped", 0))
            passed += tests - f - sk
            failed += f
            skipped += sk
    print(f"total: {passed} passed, {failed} failed, {skipped} skipped")
    return 1 if failed or passed == 0 else 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--failure"] and len(sys.argv) == 4:
        print(failure_xml(sys.argv[2], sys.argv[3]))
        sys.exit(0)
    sys.exit(main(sys.argv[1:]))
