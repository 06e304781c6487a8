//! The three answers a run gives, told truthfully: does the loop keep its deadline (`deadline`),
//! what is its latency budget (`latency_budget`), does the physical system stay within its limits
//! (`verdict`), and how does it degrade when a stage dies and stays dead (`degradation`). One test
//! binary, so that CI links it once.

mod deadline;
mod degradation;
mod latency_budget;
mod verdict;
