//! A check of a pickle's shape before it is decoded: how deeply its containers nest and how many
//! values it stands for once every memo reference is expanded. `serde-pickle` decodes nested
//! containers recursively and expands each memo reference into a copy, so a 4 KiB pickle of 2,000
//! nested lists overflows the stack (the whole process aborts) and a small pickle that references
//! one list many times, then that list of references many times, expands into gigabytes. OPNet's
//! perception pickles nest about six deep and stand for a few thousand values; anything far beyond
//! is refused here with a reason.
//!
//! The check runs the pickle machine's stack effects (Python's `pickletools` lists every opcode
//! with its argument and stack effect) without building any value: each container becomes a node,
//! each `APPEND`, `SETITEM`, `BUILD`, `REDUCE`... an edge, memo entries name nodes. Then one
//! iterative pass over that graph from the pickled value measures the depth and the expanded size,
//! refusing cycles. No recursion, and memory in proportion to the file.

use std::collections::HashMap;

/// The deepest nesting of containers accepted. OPNet's pickles nest about six deep.
pub const MAX_DEPTH: u32 = 32;
/// The most values a pickle may expand to (a value of `n` bytes counts `1 + n / 16`). OPNet's
/// perception of one video is some tens of thousands.
pub const MAX_EXPANDED: u64 = 4_000_000;

/// What the pickle machine's stack holds.
#[derive(Debug, Clone, Copy)]
enum Item {
    Mark,
    /// A value that holds no other: its weight.
    Scalar(u64),
    /// A container: a node of the graph.
    Node(u32),
}

/// The graph of containers.
#[derive(Default)]
struct Graph {
    /// Per node: the weight of the scalars it holds.
    scalars: Vec<u64>,
    /// `(parent, child)`.
    edges: Vec<(u32, u32)>,
}

impl Graph {
    fn node(&mut self) -> Result<u32, String> {
        let id = u32::try_from(self.scalars.len()).map_err(|_| "too many objects".to_owned())?;
        self.scalars.push(1);
        Ok(id)
    }

    fn add(&mut self, parent: u32, child: Item) {
        match child {
            Item::Node(c) => self.edges.push((parent, c)),
            Item::Scalar(w) => {
                self.scalars[parent as usize] = self.scalars[parent as usize].saturating_add(w)
            }
            Item::Mark => {}
        }
    }
}

/// Checks a pickle's nesting and expanded size; `Err` says what is wrong.
pub fn check(bytes: &[u8]) -> Result<(), String> {
    let root = run(bytes)?;
    measure(root.0, &root.1)
}

/// Reads the opcodes; returns the pickled value and the graph.
fn run(bytes: &[u8]) -> Result<(Item, Graph), String> {
    let mut graph = Graph::default();
    let mut stack: Vec<Item> = Vec::new();
    let mut memo: HashMap<u64, Item> = HashMap::new();
    let mut at = 0usize;
    let truncated = || "the pickle ends in the middle of an opcode".to_owned();
    let take = |at: &mut usize, n: usize| -> Result<&[u8], String> {
        let end = at.checked_add(n).filter(|e| *e <= bytes.len()).ok_or_else(truncated)?;
        let out = &bytes[*at..end];
        *at = end;
        Ok(out)
    };
    let line = |at: &mut usize| -> Result<&[u8], String> {
        let rest = &bytes[*at..];
        let n = rest.iter().position(|b| *b == b'\n').ok_or_else(truncated)?;
        *at += n + 1;
        Ok(&rest[..n])
    };
    let uint = |b: &[u8]| b.iter().rev().fold(0u64, |v, x| (v << 8) | u64::from(*x));
    let pop = |stack: &mut Vec<Item>| -> Result<Item, String> {
        match stack.pop() {
            Some(Item::Mark) | None => Err("an opcode takes more from the stack than it holds".into()),
            Some(item) => Ok(item),
        }
    };
    let pop_mark = |stack: &mut Vec<Item>| -> Result<Vec<Item>, String> {
        let mark = stack.iter().rposition(|i| matches!(i, Item::Mark)).ok_or("no MARK on the stack")?;
        let items = stack.split_off(mark + 1);
        stack.pop();
        Ok(items)
    };
    let top_node = |stack: &[Item]| -> Result<Option<u32>, String> {
        match stack.last() {
            Some(Item::Node(n)) => Ok(Some(*n)),
            Some(Item::Scalar(_)) => Ok(None),
            _ => Err("an opcode needs a value on the stack".into()),
        }
    };
    let scalar = |n: usize| Item::Scalar(1 + n as u64 / 16);
    loop {
        let op = *take(&mut at, 1)?.first().ok_or_else(truncated)?;
        match op {
            b'.' => {
                let root = pop(&mut stack)?;
                return Ok((root, graph));
            }
            // Arguments only.
            0x80 => {
                take(&mut at, 1)?;
            }
            0x95 => {
                take(&mut at, 8)?;
            }
            b'(' => stack.push(Item::Mark),
            b'0' => {
                if matches!(stack.last(), Some(Item::Mark)) {
                    stack.pop();
                } else {
                    pop(&mut stack)?;
                }
            }
            b'1' => {
                pop_mark(&mut stack)?;
            }
            b'2' => {
                let top = *stack.last().ok_or("DUP on an empty stack")?;
                stack.push(top);
            }
            // Scalars with a line argument, or fixed-size arguments.
            b'F' | b'I' | b'L' | b'S' | b'V' => {
                let n = line(&mut at)?.len();
                stack.push(scalar(n));
            }
            b'J' => {
                take(&mut at, 4)?;
                stack.push(scalar(0));
            }
            b'K' | 0x82 => {
                take(&mut at, 1)?;
                stack.push(scalar(0));
            }
            b'M' | 0x83 => {
                take(&mut at, 2)?;
                stack.push(scalar(0));
            }
            0x84 => {
                take(&mut at, 4)?;
                stack.push(scalar(0));
            }
            b'G' => {
                take(&mut at, 8)?;
                stack.push(scalar(0));
            }
            b'N' | 0x88 | 0x89 | 0x97 => stack.push(scalar(0)),
            // Length-prefixed data.
            b'T' | b'X' | b'B' | 0x8b => {
                let n = uint(take(&mut at, 4)?);
                let n = usize::try_from(n).map_err(|_| truncated())?;
                take(&mut at, n)?;
                stack.push(scalar(n));
            }
            b'U' | b'C' | 0x8c | 0x8a => {
                let n = usize::from(take(&mut at, 1)?[0]);
                take(&mut at, n)?;
                stack.push(scalar(n));
            }
            0x8d | 0x8e | 0x96 => {
                let n = uint(take(&mut at, 8)?);
                let n = usize::try_from(n).map_err(|_| truncated())?;
                take(&mut at, n)?;
                stack.push(scalar(n));
            }
            b'c' => {
                line(&mut at)?;
                line(&mut at)?;
                stack.push(scalar(0));
            }
            // Persistent ids (serde-pickle refuses them; their value is opaque here).
            b'P' => {
                line(&mut at)?;
                stack.push(scalar(0));
            }
            b'Q' | 0x98 => {
                let item = pop(&mut stack)?;
                stack.push(if op == b'Q' { scalar(0) } else { item });
            }
            // New empty containers.
            b']' | b'}' | b')' | 0x8f => {
                let n = graph.node()?;
                stack.push(Item::Node(n));
            }
            // Containers built from the items above the mark.
            b'l' | b'd' | b't' | 0x91 | b'o' => {
                let items = pop_mark(&mut stack)?;
                let n = graph.node()?;
                for item in items {
                    graph.add(n, item);
                }
                stack.push(Item::Node(n));
            }
            b'i' => {
                line(&mut at)?;
                line(&mut at)?;
                let items = pop_mark(&mut stack)?;
                let n = graph.node()?;
                for item in items {
                    graph.add(n, item);
                }
                stack.push(Item::Node(n));
            }
            // Containers built from the top items: TUPLE1-3, REDUCE, NEWOBJ, NEWOBJ_EX, STACK_GLOBAL.
            0x85..=0x87 | b'R' | 0x81 | 0x92 | 0x93 => {
                let count = match op {
                    0x85 => 1,
                    0x86 | b'R' | 0x81 | 0x93 => 2,
                    _ => 3,
                };
                let n = graph.node()?;
                for _ in 0..count {
                    let item = pop(&mut stack)?;
                    graph.add(n, item);
                }
                stack.push(Item::Node(n));
            }
            // Items added to the container below them.
            b'a' | b'b' => {
                let item = pop(&mut stack)?;
                if let Some(n) = top_node(&stack)? {
                    graph.add(n, item);
                }
            }
            b's' => {
                let value = pop(&mut stack)?;
                let key = pop(&mut stack)?;
                if let Some(n) = top_node(&stack)? {
                    graph.add(n, key);
                    graph.add(n, value);
                }
            }
            b'e' | b'u' | 0x90 => {
                let items = pop_mark(&mut stack)?;
                if let Some(n) = top_node(&stack)? {
                    for item in items {
                        graph.add(n, item);
                    }
                }
            }
            // The memo.
            b'p' | b'q' | b'r' | 0x94 => {
                let key = match op {
                    b'p' => parse_decimal(line(&mut at)?)?,
                    b'q' => uint(take(&mut at, 1)?),
                    b'r' => uint(take(&mut at, 4)?),
                    _ => memo.len() as u64,
                };
                let top = *stack.last().ok_or("PUT on an empty stack")?;
                if matches!(top, Item::Mark) {
                    return Err("PUT of a MARK".into());
                }
                memo.insert(key, top);
            }
            b'g' | b'h' | b'j' => {
                let key = match op {
                    b'g' => parse_decimal(line(&mut at)?)?,
                    b'h' => uint(take(&mut at, 1)?),
                    _ => uint(take(&mut at, 4)?),
                };
                let item =
                    *memo.get(&key).ok_or_else(|| format!("memo entry {key} used before it is set"))?;
                stack.push(item);
            }
            other => return Err(format!("unknown pickle opcode 0x{other:02x}")),
        }
    }
}

fn parse_decimal(text: &[u8]) -> Result<u64, String> {
    std::str::from_utf8(text)
        .ok()
        .and_then(|t| t.trim().parse().ok())
        .ok_or_else(|| "a memo key that is not a number".to_owned())
}

/// Depth and expanded size of the value `root`, iteratively (post-order with an explicit stack).
fn measure(root: Item, graph: &Graph) -> Result<(), String> {
    let Item::Node(root) = root else { return Ok(()) };
    let nodes = graph.scalars.len();
    // Children of each node, compressed.
    let mut start = vec![0usize; nodes + 1];
    for &(p, _) in &graph.edges {
        start[p as usize + 1] += 1;
    }
    for i in 0..nodes {
        start[i + 1] += start[i];
    }
    let mut children = vec![0u32; graph.edges.len()];
    let mut fill = start.clone();
    for &(p, c) in &graph.edges {
        children[fill[p as usize]] = c;
        fill[p as usize] += 1;
    }
    // 0: not visited, 1: on the path, 2: done.
    let mut state = vec![0u8; nodes];
    let mut depth = vec![0u32; nodes];
    let mut size = vec![0u64; nodes];
    let mut path: Vec<(u32, usize)> = vec![(root, start[root as usize])];
    state[root as usize] = 1;
    while let Some(&mut (node, ref mut next)) = path.last_mut() {
        let n = node as usize;
        if *next < start[n + 1] {
            let child = children[*next] as usize;
            *next += 1;
            match state[child] {
                0 => {
                    if path.len() as u32 >= MAX_DEPTH {
                        return Err(format!(
                            "containers nested more than {MAX_DEPTH} deep (OPNet's perception nests about 6)"
                        ));
                    }
                    state[child] = 1;
                    path.push((child as u32, start[child]));
                }
                1 => return Err("a container that contains itself".into()),
                _ => {}
            }
            continue;
        }
        path.pop();
        let kids = &children[start[n]..start[n + 1]];
        depth[n] = 1 + kids.iter().map(|&c| depth[c as usize]).max().unwrap_or(0);
        size[n] = kids.iter().fold(graph.scalars[n], |s, &c| s.saturating_add(size[c as usize]));
        if depth[n] > MAX_DEPTH {
            return Err(format!(
                "containers nested {} deep, more than {MAX_DEPTH} (OPNet's perception nests about 6)",
                depth[n]
            ));
        }
        if size[n] > MAX_EXPANDED {
            return Err(format!(
                "its references expand to more than {MAX_EXPANDED} values (OPNet's perception has some tens of thousands)"
            ));
        }
        state[n] = 2;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::check;

    /// `[[[...]]]` nested `n` deep, as protocol 2 writes it.
    fn nested(n: usize) -> Vec<u8> {
        let mut p = vec![0x80, 2];
        p.extend(std::iter::repeat_n(b']', n));
        p.extend(std::iter::repeat_n(b'a', n - 1));
        p.push(b'.');
        p
    }

    #[test]
    fn shallow_pickles_pass_deep_ones_are_refused() {
        assert_eq!(check(&nested(5)), Ok(()));
        assert!(check(&nested(2000)).unwrap_err().contains("nested"));
    }

    #[test]
    fn deep_nesting_built_through_the_memo_is_seen() {
        // Lists L0..Ln memoized first, then each appended into the next in reverse order: the stack
        // never holds more than two, yet L_n nests n deep.
        let n = 100u8;
        let mut p = vec![0x80, 2];
        for k in 0..=n {
            p.extend([b']', b'q', k, b'0']);
        }
        for k in (0..n).rev() {
            p.extend([b'h', k + 1, b'h', k, b'a', b'0']);
        }
        p.extend([b'h', n, b'.']);
        assert!(check(&p).unwrap_err().contains("nested"));
    }

    #[test]
    fn a_billion_laughs_is_refused() {
        // L = [0] * 200; then a list of 200 references to L, memoized; then 200 references to that.
        let mut p = vec![0x80, 2, b']', b'q', 0, b'('];
        p.extend(std::iter::repeat_n([b'K', 0], 200).flatten());
        p.extend([b'e', b']', b'q', 1, b'(']);
        p.extend(std::iter::repeat_n([b'h', 0], 200).flatten());
        p.extend([b'e', b']', b'(']);
        p.extend(std::iter::repeat_n([b'h', 1], 200).flatten());
        p.extend([b'e', b'.']);
        assert!(check(&p).unwrap_err().contains("expand"));
    }

    #[test]
    fn a_list_inside_itself_is_refused() {
        let p = [0x80, 2, b']', b'q', 0, b'h', 0, b'a', b'.'];
        assert!(check(&p).unwrap_err().contains("itself"));
    }

    #[test]
    fn truncated_and_unknown_opcodes_are_errors() {
        assert!(check(&[0x80, 2, b']']).is_err());
        assert!(check(&[0x80, 2, 0xff, b'.']).unwrap_err().contains("unknown"));
        assert!(check(&[0x80, 2, b'X', 0xff, 0xff, 0xff, 0x7f]).is_err());
    }
}
