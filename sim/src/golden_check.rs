//! The golden check every machine and level makes: a query's simulated result waits for the
//! golden result the stream carries right after its end, and the two must agree.

use crate::error::SimError;
use occsim_traces::QueryResult;

/// The first field where a simulated result differs from the golden one:
/// (field, simulated value, golden value).
pub(crate) type Difference = Option<(String, String, String)>;

/// Holds the last query's simulated result until its golden result arrives.
#[derive(Default)]
pub(crate) struct GoldenCheck {
    /// The query's number in stream order, and its simulated result.
    awaiting: Option<(usize, QueryResult)>,
    checked: u64,
}

impl GoldenCheck {
    /// Query number `index` (in stream order) ended with `simulated`; check it next.
    pub(crate) fn expect(&mut self, index: usize, simulated: QueryResult) {
        self.awaiting = Some((index, simulated));
    }

    /// The stream's golden result (event number `event`) for the query that just ended,
    /// compared by `difference`.
    pub(crate) fn check(
        &mut self,
        golden: &QueryResult,
        event: u64,
        difference: impl FnOnce(&QueryResult, &QueryResult) -> Difference,
    ) -> Result<(), SimError> {
        let (index, simulated) = self.awaiting.take().ok_or(SimError::ResultWithoutQuery {
            event,
            id: golden.id,
        })?;
        if let Some((field, simulated_value, golden_value)) = difference(&simulated, golden) {
            return Err(SimError::Mismatch {
                id: simulated.id,
                index,
                field,
                simulated: simulated_value,
                golden: golden_value,
            });
        }
        self.checked += 1;
        Ok(())
    }

    /// Queries whose golden result agreed.
    pub(crate) fn checked(&self) -> u64 {
        self.checked
    }
}
