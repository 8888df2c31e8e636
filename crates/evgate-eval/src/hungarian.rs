//! Optimal one-to-one assignment (Hungarian algorithm, potentials form, O(n² m)).

/// Assigns rows to columns so that the summed weight of the chosen pairs is maximal; each row
/// and each column is used at most once, and min(rows, columns) pairs are chosen.
///
/// Returns, for every row, the column it is paired with. `weights` must be rectangular (all rows
/// of the same length) and finite.
pub fn maximum_weight_assignment(weights: &[Vec<f64>]) -> Vec<Option<usize>> {
    let rows = weights.len();
    let columns = weights.first().map_or(0, Vec::len);
    if rows == 0 || columns == 0 {
        return vec![None; rows];
    }
    if rows <= columns {
        minimum_cost_rows_to_columns(rows, columns, |r, c| -weights[r][c])
    } else {
        let by_column = minimum_cost_rows_to_columns(columns, rows, |c, r| -weights[r][c]);
        let mut by_row = vec![None; rows];
        for (column, row) in by_column.into_iter().enumerate() {
            if let Some(row) = row {
                by_row[row] = Some(column);
            }
        }
        by_row
    }
}

/// Classic Hungarian algorithm for `rows ≤ columns`: every row gets a distinct column.
fn minimum_cost_rows_to_columns(
    rows: usize,
    columns: usize,
    cost: impl Fn(usize, usize) -> f64,
) -> Vec<Option<usize>> {
    // 1-based arrays with a virtual column 0, as in the textbook formulation.
    let mut row_potential = vec![0.0f64; rows + 1];
    let mut column_potential = vec![0.0f64; columns + 1];
    let mut row_of_column = vec![0usize; columns + 1];
    let mut previous_column = vec![0usize; columns + 1];
    for row in 1..=rows {
        row_of_column[0] = row;
        let mut current_column = 0usize;
        let mut slack = vec![f64::INFINITY; columns + 1];
        let mut used = vec![false; columns + 1];
        loop {
            used[current_column] = true;
            let current_row = row_of_column[current_column];
            let mut delta = f64::INFINITY;
            let mut next_column = 0usize;
            for column in 1..=columns {
                if used[column] {
                    continue;
                }
                let reduced = cost(current_row - 1, column - 1)
                    - row_potential[current_row]
                    - column_potential[column];
                if reduced < slack[column] {
                    slack[column] = reduced;
                    previous_column[column] = current_column;
                }
                if slack[column] < delta {
                    delta = slack[column];
                    next_column = column;
                }
            }
            for column in 0..=columns {
                if used[column] {
                    row_potential[row_of_column[column]] += delta;
                    column_potential[column] -= delta;
                } else {
                    slack[column] -= delta;
                }
            }
            current_column = next_column;
            if row_of_column[current_column] == 0 {
                break;
            }
        }
        loop {
            let previous = previous_column[current_column];
            row_of_column[current_column] = row_of_column[previous];
            current_column = previous;
            if current_column == 0 {
                break;
            }
        }
    }
    let mut column_of_row = vec![None; rows];
    for column in 1..=columns {
        if row_of_column[column] != 0 {
            column_of_row[row_of_column[column] - 1] = Some(column - 1);
        }
    }
    column_of_row
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn total(weights: &[Vec<f64>], assignment: &[Option<usize>]) -> f64 {
        assignment
            .iter()
            .enumerate()
            .filter_map(|(r, c)| c.map(|c| weights[r][c]))
            .sum()
    }

    fn brute_force_best(weights: &[Vec<f64>]) -> f64 {
        fn search(weights: &[Vec<f64>], row: usize, used: &mut Vec<bool>) -> f64 {
            if row == weights.len() {
                return 0.0;
            }
            // A row may stay unassigned only when there are more rows than columns.
            let mut best = if weights.len() > used.len() {
                search(weights, row + 1, used)
            } else {
                f64::NEG_INFINITY
            };
            for column in 0..used.len() {
                if !used[column] {
                    used[column] = true;
                    best = best.max(weights[row][column] + search(weights, row + 1, used));
                    used[column] = false;
                }
            }
            best
        }
        search(weights, 0, &mut vec![false; weights[0].len()])
    }

    #[test]
    fn greedy_choice_is_not_optimal_here() {
        // Greedy takes (0,0)=0.9 and is left with (1,1)=0.1; the optimum is 0.8 + 0.8.
        let weights = vec![vec![0.9, 0.8], vec![0.8, 0.1]];
        assert_eq!(maximum_weight_assignment(&weights), vec![Some(1), Some(0)]);
    }

    #[test]
    fn more_rows_than_columns_leaves_rows_unassigned() {
        let weights = vec![vec![0.1], vec![0.7], vec![0.3]];
        assert_eq!(
            maximum_weight_assignment(&weights),
            vec![None, Some(0), None]
        );
    }

    #[test]
    fn empty_matrices() {
        assert!(maximum_weight_assignment(&[]).is_empty());
        assert_eq!(
            maximum_weight_assignment(&[vec![], vec![]]),
            vec![None, None]
        );
    }

    proptest! {
        #[test]
        fn matches_brute_force(
            rows in 1usize..5,
            columns in 1usize..5,
            values in proptest::collection::vec(0.0f64..1.0, 25),
        ) {
            let weights: Vec<Vec<f64>> = (0..rows)
                .map(|r| (0..columns).map(|c| values[r * 5 + c]).collect())
                .collect();
            let assignment = maximum_weight_assignment(&weights);
            let mut seen = std::collections::HashSet::new();
            for column in assignment.iter().flatten() {
                prop_assert!(seen.insert(*column));
            }
            prop_assert_eq!(seen.len(), rows.min(columns));
            prop_assert!((total(&weights, &assignment) - brute_force_best(&weights)).abs() < 1e-9);
        }
    }
}
