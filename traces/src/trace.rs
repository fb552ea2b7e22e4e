//! The `.occt` fragment trace format. (Being written: see the trace format task.)
