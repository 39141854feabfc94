import re, os
codes = [
("E0001","Syntax error","The text does not follow the grammar. The message lists what could come at that point (punctuation, keywords, a name, a number) and what was found instead. After a syntax error the parser resumes at the next item that starts a line, so each broken item gets its own message; semantic checks run only on files without syntax errors.",["syntax_missing_brace","syntax_unknown_policy","syntax_reserved_word"]),
("E0002","Nesting too deep","Brackets (`(`, `[`, `{`, `list<`) may nest at most 64 deep, and an expression at most 256 operators deep. The limits keep parsing and checking from exhausting the stack on hostile input; real specs stay far below them.",["nesting_too_deep"]),
("E0003","Number out of range","Integers are 64-bit signed; floats must be finite (`1e999` is not).",["number_out_of_range"]),
("E0004","Unknown escape in a string","Strings accept the escapes `\\\"`, `\\\\`, `\\n`, `\\t`, `\\r` and `\\0`.",["bad_escape"]),
("E0005","File too large","Spec files may be at most 64 MiB. Split larger specs.",[]),
("E0006","Chained comparison","`a < b < c` is not allowed; write `a < b and b < c`.",["chained_comparison"]),
("E0007","Invalid duration","Durations are non-negative, count whole microseconds, and must fit in 64 bits.",["bad_duration"]),
("E0008","Not UTF-8","Spec files are UTF-8 text; the diagnostic points at the first invalid byte.",["not_utf8"]),
("E0101","Unknown name","A stream, process or formula name that is not declared. A hint proposes the closest existing name.",["unknown_stream"]),
("E0102","Defined more than once","Processes and streams share one namespace; types, attributes, parameters, prediction models per type and forget times per type must also be unique.",["duplicate_name"]),
("E0103","Unknown attribute","The type has no attribute of that name (inherited attributes count). The hint names the closest attribute or lists them all.",["unknown_attribute"]),
("E0104","Type mismatch","A value of the wrong type: a formula that is not boolean, arithmetic on a vector and a number, a declared output type that the registered source cannot produce, an input stream of the wrong type.",["type_mismatch_formula","type_mismatch_arithmetic","type_mismatch_output"]),
("E0105","Unknown type","A type name that is neither built in (`bool`, `int`, `float`, `string`, `vec2`, `box`, `duration`, `list<T>`, `any`) nor declared with `type`.",["unknown_type"]),
("E0106","Cyclic type hierarchy","Following the parents of a type (and the types of its attributes) must end; a type cannot inherit from itself.",["type_cycle"]),
("E0107","Unknown function","A function or predicate that is neither built in nor provided by the link unit of the link the condition belongs to (`kpl list` shows both).",["unknown_function"]),
("E0108","Wrong number of arguments","A function called with too many or too few arguments.",["wrong_arity"]),
("E0109","Symbol prefix used twice","Each object type's instances get symbols with its prefix (`vp8`, `wo5`); two types with one prefix would make symbols ambiguous. Without `symbol`, the prefix is the lower-cased initials of the type name.",["duplicate_symbol"]),
("E0110","Unknown source, unit, sink or model","The name is not in the runtime's registry for that kind of process. If it exists as another kind, the hint says so.",["unknown_entry","entry_wrong_kind"]),
("E0111","Unknown parameter","The registry entry has no parameter of that name.",["unknown_param"]),
("E0112","Missing parameter","A required parameter (one without a default) is not given.",["missing_param"]),
("E0113","Parameter of the wrong type","A parameter value of the wrong kind, or a string that is not one of the allowed choices.",["param_type","param_choice"]),
("E0114","Wrong number of input streams","Positional arguments are input streams; their number must match the entry's inputs.",["input_count"]),
("E0115","Not a stream","An input must name a declared stream or a process with an output; sinks and types are not streams, and a stream's source must be a process.",["not_a_stream","type_as_stream"]),
("E0116","Unknown output","`process.port` names an output the process does not have (links have `changes`).",["unknown_port"]),
("E0117","Built-in type redefined","`bool`, `int`, `float`, `string`, `vec2`, `box`, `duration` and `list` cannot be declared as object types.",["builtin_type"]),
("E0120","Conflicting policies","Policies that cannot hold together on one stream: `sample every` needs samples in time order (not `any order`) and an approximation to fill instants without a sample (not `no approximation`).",["policy_conflict_order","policy_conflict_approximation"]),
("E0121","Two policies of one kind","A stream has at most one policy of each kind (approximation, change, delay, duration, order, queue, feedback).",["policy_duplicate"]),
("E0122","Invalid policy value","A queue of size 0, a duration window that ends before it starts, or `sample every 0s`.",["policy_value"]),
("E0130","Cycle in the stream graph","Processes that feed each other must be cut by a delayed edge: declare one stream of the cycle `with feedback`, so the consumer reads the producer's previous sample (as AAPA reads its previous world model).",["cycle"]),
("E0140","Process not placed","With a `deploy` section, every process (source, compute, link, monitor, sink) must be placed on a host.",["not_placed"]),
("E0141","Process placed twice","A process runs on exactly one host.",["placed_twice"]),
("E0142","Unknown process in deploy","A host lists a name that is not a process.",["unknown_placed"]),
("E0143","Stream placed","Streams are not placed: a stream's policy runs where each consumer runs, and streams between hosts go over zenoh by themselves.",["stream_placed"]),
("E0144","Host declared twice","Each host has one `host` block.",["duplicate_host"]),
("E0145","Two deploy sections","A spec has at most one `deploy` section.",["deploy_twice"]),
("E0146","Invalid zenoh endpoint","Endpoints are zenoh locators `PROTOCOL/ADDRESS`, with a port for tcp, udp, tls, quic and ws (`tcp/127.0.0.1:7447`).",["bad_endpoint"]),
("E0147","Link protocol not built in","kpl links hosts over `tcp/` and `tls/` (TLS needs the deployment's keys: `kpl keys`, then `kpl run --keys`); an endpoint of another protocol could not be opened by `kpl run`, so `kpl check` refuses it.",["protocol_not_built_in"]),
("E0148","Empty deployment name","`deploy NAME { ... }` names the deployment (part of every key between its hosts); the name cannot be empty. Leave it out to use `default`, or give one with `kpl run --deployment`.",["empty_deployment_name"]),
("E0150","Link condition missing","A link specification needs `establish`, `reestablish` and `maintain` conditions.",["condition_missing"]),
("E0151","Link condition given twice","Each condition appears once in a link; combine alternatives with `and` / `or`.",["condition_twice"]),
("E0152","No producer of a type","A link from type A (or a monitor quantifying over A) needs a process that produces objects of exactly type A: a source or compute declared with that type, or a link `... -> A`. Name another stream with `input`.",["no_producer"]),
("E0153","`to` in an establish condition","Establish decides whether to create a new object, so only `from` exists there.",["to_in_establish"]),
("E0154","Link input of the wrong type","The stream named by `input` must carry objects of the link's from-type (or a subtype).",["link_input_type"]),
("E0155","Reserved attribute name","Every object has the attributes `id` (its symbol), `measured` (whether anchoring measured its state at this state) and `predicted_since` (since when it has not), and the branches of a prediction `likelihood` and `branch_of`; a type cannot declare attributes of these names.",["reserved_attribute"]),
("E0156","Link objects only through feedback","A link process steps at the states of its inputs, and a `feedback` input is never waited for, so a link whose `from` streams are all `feedback` would never step.",["link_input_feedback"]),
("E0160","Empty interval","An interval's lower bound is above its upper bound.",["bad_interval"]),
("E0161","Invalid interval bound","`inf` as a lower bound, or a bound too large. In a spec a bare integer bound counts milliseconds (the DyKnow paper's unit).",["bad_bound"]),
("W0201","Unused stream","A declared stream that no process consumes. Reported only for files without errors.",["unused_stream"]),
("W0202","Unused output","A source or computational unit whose output nothing consumes. Reported only for files without errors.",["unused_output"]),
("W0203","Bare number in a time bound","A bare number in an interval bound counts milliseconds (the DyKnow paper's unit), so `eventually[0, 3]` is 3 ms, which is rarely what was meant. The hint writes the interval with units; write `ms` to keep milliseconds, `s` or `min` otherwise. A bare `0` is fine.",["bare_bound"]),
("W0204","Attribute nothing sets","Every process that produces objects of the type is a link unit that declares which attributes it sets (`kpl list`), and none sets this one: it keeps its default (0, false, \"\") for ever, so a formula reading it is silently wrong. `anchor.copy` sets what the linked-from object also has, `anchor.snap_to_lane` adds `road` and `lane_offset`. Sources and units that do not declare what they set count as setting everything. Reported only for files without errors.",["unset_attribute"]),
]
def example(name, code):
    for d in ("specs/err","specs/warn"):
        p=f"{d}/{name}.diagnostics"
        if os.path.exists(p):
            text=open(p).read()
            blocks=text.split("\n\n")
            for b in blocks:
                if f"[{code}]" in b:
                    src=open(f"{d}/{name}.kpl", errors="replace").read()
                    return p.replace(".diagnostics",".kpl"), b.strip()
    raise SystemExit(f"no example for {code} in {name}")
out=["# Diagnostics","","Every problem `kpl check` (and `kpl graph`, `kpl fmt`) reports has a stable code. Errors (`E...`) make",
"`kpl check` exit with status 1; warnings (`W...`) do not. `E00xx` are syntax errors (no semantic checks run on a",
"file with syntax errors), `E01xx` semantic errors, `W02xx` warnings. All semantic errors of a file are reported",
"in one run.","","Each example below is the rendered output of a spec in `specs/err/` or `specs/warn/`; the test",
"`kpl/tests/specs.rs` keeps those outputs (and this list of codes) in step with the code.","",
"`--format json` prints the same diagnostics as one JSON array of objects with the fields `file`, `line`,",
"`column`, `end_line`, `end_column` (1-based; the end column is just past the span), `severity` (`error` or",
"`warning`), `code`, `message`, when there is one, `hint`, and `labels`: every marked place, the primary span",
"first and the others in source order, each with `line`, `column`, `end_line`, `end_column`, `primary` and",
"`message` (the text under the span; empty when there is none).","",
"`kpl explain CODE` prints the section of a code below (the text is built into `kpl`).",""]
for code,title,text,examples in codes:
    out.append(f"## {code}: {title}")
    out.append("")
    out.append(text)
    out.append("")
    for name in examples:
        path, block = example(name, code)
        out.append(f"From `{path}`:")
        out.append("")
        out.append("```text")
        out.append(block)
        out.append("```")
        out.append("")
    if not examples and code=="E0005":
        out.append("```text\nerror[E0005]: file is too large (70000000 bytes)\n --> big.kpl:1:1\n  |\n1 | type A { x: int }\n  | ^\n  = hint: spec files may be at most 64 MiB; split the spec\n```\n")
open("docs/diagnostics.md","w").write("\n".join(out).rstrip()+"\n")
