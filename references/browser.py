"""A headless browser for the preview's page: Debian's Chromium driven by Selenium. Test
infrastructure (tests/conftest.py's ``browser`` fixture) that the preview benchmark
(scripts/bench_preview.py) shares; selenium is imported on first use."""

from __future__ import annotations

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"  # Debian's chromium, chromium-driver
# Headless as root in a container, and none of Chromium's own connections (refused here, slowly).
CHROMIUM_FLAGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-quic",
                  "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--window-size=1400,1000")


def headless_chromium():
    """A Selenium driver of Debian's Chromium, headless (selenium imported here, on first use)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
