//! The call graph: each function analysed once (callees first, so that a
//! caller knows which registers a call preserves), then the deepest path
//! below each function, failing on recursion that grows the stack.

use std::collections::{BTreeMap, BTreeSet, VecDeque};

use super::flow::{self, Callee, Facts, Summary};
use super::image::Image;
use super::pointer::Class;

/// A node of the call graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Node {
    /// A function, by entry address.
    Fn(u32),
    /// A call through a function pointer the analysis could not resolve:
    /// a function whose address the image stores or passes around, of
    /// those the call's place allows ([`Class`]).
    Pointer(Class),
}

/// How deep the stack goes below a node.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Depth {
    /// Bytes below the node's entry SP, its callees included.
    pub below: u32,
    /// The deepest of those where an interrupt may preempt (`None`: it
    /// runs with interrupts masked throughout).
    pub open: Option<u32>,
    /// Bytes below the top of the stack on paths that restart the stack
    /// (`msr msp`), 0 if none.
    pub fresh: u32,
}

/// A node in context: the panic handler's runs on the path to it, and
/// whether it is entered with interrupts masked.
type Key = (Node, u8, bool);

/// Where a node's deepest paths go next (the callee's key), for
/// [`Graph::path`]: the deepest, the deepest preemptible, the deepest on a
/// restarted stack (and whether that call is the one restarting it).
#[derive(Clone, Copy, Debug, Default)]
struct Via {
    below: Option<(Key, u32)>,
    open: Option<(Key, u32)>,
    fresh: Option<(Key, u32, bool)>,
}

/// A call between nodes.
#[derive(Clone, Copy, Debug)]
struct Edge {
    /// The caller's frame depth at the call.
    depth: u32,
    /// On a restarted stack.
    fresh: bool,
    /// The callee.
    to: Key,
}

/// Tarjan's bookkeeping.
#[derive(Default)]
struct Tarjan {
    next: u32,
    index: BTreeMap<Key, u32>,
    low: BTreeMap<Key, u32>,
    stack: Vec<Key>,
    edges: BTreeMap<Key, Vec<Edge>>,
}

/// The analysed functions of one image.
pub struct Graph<'a> {
    image: &'a Image,
    /// Each function entered with interrupts enabled.
    summaries: BTreeMap<u32, Summary>,
    /// Each function entered with interrupts masked (analysed on demand).
    masked: BTreeMap<u32, Summary>,
    in_progress: BTreeSet<u32>,
    depths: BTreeMap<Key, (Depth, Via)>,
    /// The functions a call through an unresolved pointer may reach.
    taken: BTreeSet<u32>,
    /// Functions whose calls are not followed (`Chip::overflow_on_purpose`).
    on_purpose: &'static [&'static str],
}

impl<'a> Graph<'a> {
    /// An empty graph over `image`.
    pub fn new(image: &'a Image, on_purpose: &'static [&'static str]) -> Graph<'a> {
        Graph {
            image,
            on_purpose,
            summaries: BTreeMap::new(),
            masked: BTreeMap::new(),
            in_progress: BTreeSet::new(),
            depths: BTreeMap::new(),
            taken: BTreeSet::new(),
        }
    }

    /// Analyses the function at `entry` (and what it calls), giving what a
    /// caller needs to know of it. A function reached again while it is
    /// being analysed (recursion) counts as changing nothing and never
    /// returning for now: [`Graph::stabilise`] then analyses again until
    /// nothing changes.
    pub fn facts(&mut self, entry: u32) -> Result<Facts, String> {
        if let Some(s) = self.summaries.get(&entry) {
            return Ok(s.facts);
        }
        if self.in_progress.contains(&entry) {
            return Ok(Facts {
                clobbers: super::insn::Regs::NONE,
                returns: false,
            });
        }
        if !self.image.insns.contains_key(&entry) {
            return Err(format!(
                "a call to {}, which is not an instruction",
                self.image.name(entry)
            ));
        }
        self.in_progress.insert(entry);
        let image = self.image;
        let summary = flow::analyse(image, entry, false, &mut |t| self.facts(t));
        self.in_progress.remove(&entry);
        let summary = summary?;
        let facts = summary.facts;
        self.summaries.insert(entry, summary);
        Ok(facts)
    }

    /// Analyses every function again until no function's facts change:
    /// the least fixed point for recursive functions (a register is
    /// changed, a function returns, only if some path does so).
    pub fn stabilise(&mut self) -> Result<(), String> {
        for _ in 0..100 {
            let mut changed = false;
            let entries: Vec<u32> = self.summaries.keys().copied().collect();
            for e in entries {
                let image = self.image;
                let s = flow::analyse(image, e, false, &mut |t| self.facts(t))?;
                changed |= s.facts != self.summaries[&e].facts;
                self.summaries.insert(e, s);
            }
            if !changed {
                return Ok(());
            }
        }
        Err("the analysis of recursive functions does not settle".into())
    }

    /// Analyses every function a call through an unresolved pointer may
    /// reach, and what they call, until the set is complete, with the
    /// facts of recursive functions settled ([`Graph::stabilise`]).
    ///
    /// Such a call may reach a function whose address is stored in the
    /// image's data (vtables, tables of functions), or that some analysed
    /// code stores, passes to a call or returns, or whose address sits in
    /// a literal pool that no analysed code loads as a constant. A function
    /// whose address the code only loads to call it is not among them.
    pub fn close(&mut self) -> Result<(), String> {
        loop {
            self.stabilise()?;
            if !self.has_unknown_calls() {
                return Ok(());
            }
            let mut loaded = BTreeSet::new();
            let mut taken = self.image.data_refs.clone();
            for s in self.summaries.values() {
                loaded.extend(s.literals.iter().copied());
                taken.extend(s.escapes.iter().copied());
            }
            for &(at, f) in &self.image.pool_refs {
                if !loaded.contains(&at) {
                    taken.insert(f);
                }
            }
            let before = self.summaries.len();
            for &t in &taken {
                self.facts(t)?;
            }
            let grown = taken != self.taken || self.summaries.len() != before;
            self.taken = taken;
            if !grown {
                return self.stabilise();
            }
        }
    }

    /// Whether some analysed call goes through a pointer the analysis
    /// could not resolve.
    pub fn has_unknown_calls(&self) -> bool {
        self.summaries
            .values()
            .any(|s| s.sites.iter().any(|site| site.callee == Callee::Unknown))
    }

    /// Every analysed function.
    pub fn summaries(&self) -> impl Iterator<Item = &Summary> {
        self.summaries.values()
    }

    /// The summary of a function entered with interrupts masked or not.
    fn summary(&mut self, entry: u32, masked: bool) -> Result<&Summary, String> {
        self.facts(entry)?;
        if !masked {
            return Ok(&self.summaries[&entry]);
        }
        if !self.masked.contains_key(&entry) {
            let image = self.image;
            let s = flow::analyse(image, entry, true, &mut |t| self.facts(t))?;
            self.masked.insert(entry, s);
        }
        Ok(&self.masked[&entry])
    }

    /// How deep the stack goes below `node`, entered with interrupts
    /// enabled. Fails on recursion that grows the stack, naming the
    /// cycle. (A cycle that adds nothing, such as a waker's tail call
    /// through a function pointer, is harmless.)
    pub fn depth(&mut self, node: Node) -> Result<Depth, String> {
        let key = (node, 0, false);
        if !self.depths.contains_key(&key) {
            let mut t = Tarjan::default();
            self.connect(key, &mut t)?;
        }
        Ok(self.depths[&key].0)
    }

    /// The calls out of a node: to nodes with the panic handler's runs on
    /// the path counted. A panic inside the panic handler (the logger's
    /// re-entrancy check) finds the handler's flag set and goes straight
    /// to the end state, so the handler runs at most twice on one path:
    /// the second run counts in full (more than its path to the end
    /// state), a third is not followed.
    fn edges(&mut self, key: Key) -> Result<Vec<Edge>, String> {
        let (node, panics, masked) = key;
        let mut edges = Vec::new();
        let to = |g: &Graph, c: Node, masked: bool| {
            let inner = panics + u8::from(g.is_panic_handler(c));
            (inner <= 2).then_some((c, inner, masked))
        };
        match node {
            Node::Pointer(class) => {
                for t in self.pointer_targets(class) {
                    if let Some(k) = to(self, Node::Fn(t), masked) {
                        edges.push(Edge {
                            depth: 0,
                            fresh: false,
                            to: k,
                        });
                    }
                }
            }
            Node::Fn(entry) if self.overflows_on_purpose(entry) => {}
            Node::Fn(entry) => {
                let sites = self.summary(entry, masked)?.sites.clone();
                for site in &sites {
                    let callees: Vec<Node> = match &site.callee {
                        Callee::Known(ts) => ts.iter().map(|&t| Node::Fn(t)).collect(),
                        Callee::Unknown => {
                            let frames = self.image.call_frames.get(&site.at);
                            let class = Class::of(frames.map_or(&[][..], |v| v));
                            if self.pointer_targets(class).is_empty() {
                                return Err(format!(
                                    "{}: a call through a register the analysis cannot \
                                     resolve, and no function of the image may be called \
                                     through a pointer from there",
                                    self.image.name(site.at)
                                ));
                            }
                            vec![Node::Pointer(class)]
                        }
                    };
                    for c in callees {
                        if let Some(k) = to(self, c, site.masked) {
                            edges.push(Edge {
                                depth: site.depth,
                                fresh: site.fresh,
                                to: k,
                            });
                        }
                    }
                }
            }
        }
        Ok(edges)
    }

    /// Whether the function at `entry` exhausts the stack on purpose.
    fn overflows_on_purpose(&self, entry: u32) -> bool {
        let name = self.image.name(entry);
        self.on_purpose.iter().any(|f| name.ends_with(f))
    }

    /// Tarjan's strongly connected components over the calls from `v`;
    /// each component's depth is set once the components it calls have
    /// theirs.
    fn connect(&mut self, v: Key, t: &mut Tarjan) -> Result<(), String> {
        let index = t.next;
        t.next += 1;
        t.index.insert(v, index);
        t.low.insert(v, index);
        t.stack.push(v);
        let edges = self.edges(v)?;
        for e in &edges {
            let w = e.to;
            if self.depths.contains_key(&w) {
                continue;
            }
            let low = match t.index.get(&w) {
                None => {
                    self.connect(w, t)?;
                    t.low[&w]
                }
                Some(&iw) if t.stack.contains(&w) => iw,
                Some(_) => continue,
            };
            if let Some(lv) = t.low.get_mut(&v) {
                *lv = (*lv).min(low);
            }
        }
        t.edges.insert(v, edges);
        if t.low[&v] != index {
            return Ok(());
        }
        let mut members = Vec::new();
        while let Some(w) = t.stack.pop() {
            members.push(w);
            if w == v {
                break;
            }
        }
        self.settle(&members, t)
    }

    /// Sets the depth of one strongly connected component: the deepest of
    /// its members' own frames and of its calls out, once the calls inside
    /// it are shown to add nothing.
    fn settle(&mut self, members: &[Key], t: &Tarjan) -> Result<(), String> {
        let mut d = Depth::default();
        // The member with the deepest of each kind, and the callee.
        type Best = Option<(Key, Key, u32)>;
        type BestFresh = Option<(Key, Key, u32, bool)>;
        let mut via: (Best, Best, BestFresh) = (None, None, None);
        for &m in members {
            if let Node::Fn(f) = m.0 {
                let s = self.summary(f, m.2)?;
                d.below = d.below.max(s.frame);
                d.fresh = d.fresh.max(s.fresh_frame.unwrap_or(0));
                d.open = max_open(d.open, s.open_frame);
            } else if !m.2 {
                // Entering a function through a pointer, unmasked.
                d.open = max_open(d.open, Some(0));
            }
        }
        for &m in members {
            for e in &t.edges[&m] {
                if members.contains(&e.to) {
                    if e.depth > 0 || e.fresh {
                        return Err(self.recursion(members, t, m, e));
                    }
                    continue;
                }
                let cd = self.depths[&e.to].0;
                let total = e.depth.saturating_add(cd.below);
                if e.fresh {
                    if total > d.fresh {
                        d.fresh = total;
                        via.2 = Some((m, e.to, e.depth, true));
                    }
                } else {
                    if total > d.below {
                        d.below = total;
                        via.0 = Some((m, e.to, e.depth));
                    }
                    if let Some(o) = cd.open {
                        let open = e.depth.saturating_add(o);
                        if d.open.is_none_or(|d| open > d) {
                            d.open = Some(open);
                            via.1 = Some((m, e.to, e.depth));
                        }
                    }
                }
                if cd.fresh > d.fresh {
                    d.fresh = cd.fresh;
                    via.2 = Some((m, e.to, e.depth, false));
                }
            }
        }
        for &m in members {
            // A member other than the one with the deepest call reaches it
            // through the component, adding nothing.
            let pick = |v: Best| v.map(|(b, to, d)| if b == m { (to, d) } else { (b, 0) });
            let v = Via {
                below: pick(via.0),
                open: pick(via.1),
                fresh: via.2.map(|(b, to, d, started)| {
                    if b == m {
                        (to, d, started)
                    } else {
                        (b, 0, false)
                    }
                }),
            };
            self.depths.insert(m, (d, v));
        }
        Ok(())
    }

    /// The error for a cycle through the call `e` out of `from` that
    /// grows the stack: the cycle's functions.
    fn recursion(&self, members: &[Key], t: &Tarjan, from: Key, e: &Edge) -> String {
        // Breadth-first from the callee back to `from`, inside the component.
        let mut prev: BTreeMap<Key, Key> = BTreeMap::new();
        let mut queue = VecDeque::from([e.to]);
        while let Some(k) = queue.pop_front() {
            if k == from {
                break;
            }
            for n in &t.edges[&k] {
                if members.contains(&n.to) && n.to != e.to && !prev.contains_key(&n.to) {
                    prev.insert(n.to, k);
                    queue.push_back(n.to);
                }
            }
        }
        // The path from the callee back to `from`, then the call itself.
        let mut cycle = vec![from];
        let mut k = from;
        while let Some(&p) = prev.get(&k) {
            cycle.push(p);
            k = p;
        }
        if k != e.to {
            cycle.push(e.to);
        }
        cycle.push(from);
        cycle.reverse();
        let names: Vec<String> = cycle.iter().map(|k| self.node_name(k.0)).collect();
        format!(
            "recursion: {} (the stack it needs has no bound; {} makes the call with {} B of frame)",
            names.join(" → "),
            self.node_name(from.0),
            e.depth
        )
    }

    /// The functions a call through an unresolved pointer of this class
    /// may reach.
    fn pointer_targets(&self, class: Class) -> Vec<u32> {
        let image = self.image;
        self.taken
            .iter()
            .copied()
            .filter(|t| class.may_reach(image.aliases.get(t).map_or(&[][..], |v| v)))
            .collect()
    }

    fn is_panic_handler(&self, n: Node) -> bool {
        match n {
            Node::Fn(a) => self.image.functions.get(&a).is_some_and(|name| {
                name == "rust_begin_unwind" || name.ends_with("::rust_begin_unwind")
            }),
            Node::Pointer(_) => false,
        }
    }

    /// The functions of a deepest path below `node` (the deepest, the
    /// deepest preemptible one, or the deepest on a restarted stack), each
    /// with the bytes it adds: its frame's depth at the call to the next,
    /// or the deepest its own frame goes for the last.
    pub fn path(&self, node: Node, kind: PathKind) -> Vec<(Node, u32)> {
        let mut path: Vec<(Node, u32)> = Vec::new();
        let mut key = (node, 0u8, false);
        let mut fresh = kind == PathKind::Fresh;
        let mut own = 0;
        while path.len() < 64 {
            let Some((_, via)) = self.depths.get(&key) else {
                break;
            };
            let next = if fresh {
                via.fresh.map(|(c, d, started)| {
                    fresh = !started;
                    (c, d)
                })
            } else if kind == PathKind::Open {
                via.open
            } else {
                via.below
            };
            let Some((next, d)) = next else { break };
            own += d;
            if next.0 != key.0 {
                path.push((key.0, own));
                own = 0;
            }
            key = next;
        }
        let last = match key.0 {
            Node::Fn(f) => self.summaries.get(&f).map_or(0, |s| {
                if kind == PathKind::Fresh {
                    s.fresh_frame.unwrap_or(s.frame)
                } else {
                    s.frame
                }
            }),
            Node::Pointer(_) => 0,
        };
        path.push((key.0, own + last));
        path
    }

    /// A node's name.
    pub fn node_name(&self, n: Node) -> String {
        match n {
            Node::Fn(a) => self.image.name(a),
            Node::Pointer(c) => c.name().into(),
        }
    }
}

/// Which of a node's deepest paths.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathKind {
    /// The deepest.
    Below,
    /// The deepest where interrupts may preempt.
    Open,
    /// The deepest on a restarted stack.
    Fresh,
}

fn max_open(a: Option<u32>, b: Option<u32>) -> Option<u32> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.max(b)),
        (a, None) => a,
        (None, b) => b,
    }
}
