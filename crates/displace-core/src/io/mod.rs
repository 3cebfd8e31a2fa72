//! File formats. OWNED BY HELPER: to be implemented.
