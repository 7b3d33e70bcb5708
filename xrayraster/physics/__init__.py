"""From path lengths to detector signals: spectra, detector, spectral Beer-Lambert, noise, radiographs."""
