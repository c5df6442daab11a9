-- Dissection of the skinbox datagrams. `skinbox wireshark` puts the tables generated from
-- the protocol crate (P: byte positions, F: fields, C: constants, CHANNELS, COUNTERS) in
-- front of this file; every position and value below comes from them.

local skinbox = Proto("skinbox", "skinbox interface box")

local fields = {}
for _, group in pairs(F) do
    for _, f in pairs(group) do
        fields[#fields + 1] = f
    end
end
skinbox.fields = fields

local E = {
    sequence_gap = ProtoExpert.new("skinbox.expert.sequence_gap",
        "Datagrams missing before this one", expert.group.SEQUENCE, expert.severity.WARN),
    sequence_late = ProtoExpert.new("skinbox.expert.sequence_late",
        "Late datagram: arrived after a higher sequence number", expert.group.SEQUENCE,
        expert.severity.NOTE),
    sequence_duplicate = ProtoExpert.new("skinbox.expert.sequence_duplicate",
        "Duplicate datagram", expert.group.SEQUENCE, expert.severity.NOTE),
    sequence_restart = ProtoExpert.new("skinbox.expert.sequence_restart",
        "Sequence numbering restarted", expert.group.SEQUENCE, expert.severity.WARN),
    box_reset = ProtoExpert.new("skinbox.expert.box_reset",
        "Box reset: the boot id changed", expert.group.SEQUENCE, expert.severity.WARN),
    event_gap = ProtoExpert.new("skinbox.expert.event_gap",
        "Event packets of this cell missing before this one", expert.group.SEQUENCE,
        expert.severity.WARN),
    bad_end_byte = ProtoExpert.new("skinbox.expert.bad_end_byte",
        "Cell packet's end byte is wrong", expert.group.MALFORMED, expert.severity.ERROR),
    unknown_version = ProtoExpert.new("skinbox.expert.unknown_version",
        "Unknown datagram version", expert.group.MALFORMED, expert.severity.ERROR),
    malformed = ProtoExpert.new("skinbox.expert.malformed",
        "Malformed skinbox datagram", expert.group.MALFORMED, expert.severity.ERROR),
}
skinbox.experts = { E.sequence_gap, E.sequence_late, E.sequence_duplicate,
    E.sequence_restart, E.box_reset, E.event_gap, E.bad_end_byte, E.unknown_version,
    E.malformed }

skinbox.prefs.udp_port = Pref.uint("UDP port", C.udp_port,
    "UDP port of the box's datagrams (the heuristic also finds them on any other port)")
skinbox.prefs.end_of_packet = Pref.uint("Cell end-of-packet byte", C.end_of_packet,
    "The cells' end-of-packet value (the box's CellFraming parameter)")

-- Per-box state of the first pass, and what it concluded about each frame (the GUI
-- dissects frames again in any order; it then reads the conclusions).
local boxes = {}
local verdicts = {}

function skinbox.init()
    boxes = {}
    verdicts = {}
end

local function pos(format, name)
    local p = P[format][name]
    return p[1], p[2]
end

local function add(tree, buf, base, format, name)
    local off, len = pos(format, name)
    return tree:add(F[format][name], buf(base + off, len))
end

local function uint(buf, base, format, name)
    local off, len = pos(format, name)
    return buf(base + off, len):uint()
end

-- A malformation the documents list (docs/wire-format.md, "What a reader refuses").
local function malformed(item, message)
    item:add_proto_expert_info(E.malformed, message)
end

-- Why a box counter block is malformed, or nil.
local function box_counters_fault(buf, base)
    local link_up = uint(buf, base, "box_counters", "link_up")
    if link_up > 1 then
        return "box counters: link_up " .. link_up .. " is not 0 or 1"
    end
    local speed = uint(buf, base, "box_counters", "link_speed")
    if speed > C.max_link_speed then
        return "box counters: link_speed " .. speed .. " is above " .. C.max_link_speed
    end
    if uint(buf, base, "box_counters", "reserved") ~= 0 then
        return "box counters: reserved bytes not 0"
    end
    return nil
end

-- Why a 20-byte cell command packet at `base` is malformed, or nil.
local function cell_command_fault(buf, base)
    local len = C.cell_packet_len
    if buf(base, 1):uint() ~= C.cc_header then
        return string.format("cell command packet: header 0x%02x is not 0x%02x",
            buf(base, 1):uint(), C.cc_header)
    end
    if buf(base + len - 1, 1):uint() ~= skinbox.prefs.end_of_packet then
        return string.format("cell command packet: end byte 0x%02x is wrong",
            buf(base + len - 1, 1):uint())
    end
    if buf(base + 1, 2):uint() > C.max_cell_id then
        return "cell command packet: cell id above 14 bits"
    end
    local code = buf(base + 3, 1):uint()
    local args_end = C.cc_arguments_end[code]
    if args_end == nil then
        return "cell command packet: unknown command " .. code
    end
    local arg = buf(base + 4, 1):uint()
    if code == C.cc_mode and arg > C.cc_max_mode then
        return "cell command packet: mode " .. arg .. " is above " .. C.cc_max_mode
    end
    if code == C.cc_rate and arg > C.cc_max_rate then
        return "cell command packet: rate code " .. arg .. " is above " .. C.cc_max_rate
    end
    if code == C.cc_enable and bit32.band(buf(base + 4, 2):uint(), C.cc_enable_reserved) ~= 0 then
        return "cell command packet: enable mask bits 9-15 set"
    end
    for i = args_end, len - 2 do
        if buf(base + i, 1):uint() ~= 0 then
            return "cell command packet: byte " .. i .. " after the arguments is not 0"
        end
    end
    return nil
end

-- Length of a whole datagram of `kind` with `entries` entries and `flags`, or nil for an
-- unknown kind (a status datagram with the box counter flag carries the block after its
-- port counters).
local function datagram_len(kind, entries, flags)
    local entry_len = C.entry_len[kind]
    if entry_len == nil then
        return nil
    end
    local len = C.header_len + C.fixed_len[kind] + entries * entry_len
    if kind ~= C.kind_records and bit32.band(flags, C.flag_box_counters) ~= 0 then
        len = len + C.box_counters_len
    end
    return len
end

-- Most entries of a datagram of `kind` with `flags`.
local function max_entries(kind, flags)
    if kind ~= C.kind_records and bit32.band(flags, C.flag_box_counters) ~= 0 then
        return C.max_status_ports_with_box_counters
    end
    return C.max_entries[kind]
end

local function dissect_box_counters(buf, tree, base)
    local bt = tree:add(F.box_counters.block, buf(base, C.box_counters_len))
    for _, name in ipairs(ROWS.box_counters) do
        add(bt, buf, base, "box_counters", name)
    end
    local refused = 0
    for _, name in ipairs(BOX_COUNTERS) do
        if string.sub(name, 1, 8) == "refused_" then
            refused = refused + uint(buf, base, "box_counters", name)
        end
    end
    bt:set_text(string.format(
        "Box counters: link %s, %d frames received, %d commands accepted, %d refused",
        uint(buf, base, "box_counters", "link_up") == 1 and "up" or "down",
        uint(buf, base, "box_counters", "frames_received"),
        uint(buf, base, "box_counters", "commands_accepted"), refused))
    local fault = box_counters_fault(buf, base)
    if fault ~= nil then
        malformed(bt, fault)
    end
end

local function dissect_destination(buf, tree, base)
    local dt = tree:add(F.destination.block, buf(base, C.destination_len))
    for _, name in ipairs(ROWS.destination) do
        add(dt, buf, base, "destination", name)
    end
    local text = string.format("%s:%d", tostring(buf(base + P.destination.ip[1], 4):ipv4()),
        uint(buf, base, "destination", "port"))
    dt:set_text("Destination: " .. text)
    return text
end

-- A command (kind 3) or an acknowledgement (kind 4).
local function dissect_control(buf, pinfo, root, kind)
    local len = buf:len()
    local format = "ack"
    local length_field = "body_length"
    if kind == C.kind_command then
        format = "command"
        length_field = "argument_length"
    end
    for _, name in ipairs(ROWS[format]) do
        add(root, buf, 0, format, name)
    end
    local box_id = uint(buf, 0, format, "box_id")
    local sequence = uint(buf, 0, format, "sequence")
    local body_len = uint(buf, 0, format, length_field)
    if len ~= C.header_len + body_len then
        root:add_proto_expert_info(E.malformed, string.format(
            "%d bytes, but the header announces %d", len, C.header_len + body_len))
        pinfo.cols.info:set("skinbox: length does not match the header")
        return len
    end
    local base = C.header_len
    if uint(buf, 0, format, "flags") ~= 0 then
        malformed(root, string.format("flags 0x%02x are not 0", uint(buf, 0, format, "flags")))
    end
    if uint(buf, 0, format, "reserved") ~= 0 then
        malformed(root, "header reserved bytes not 0")
    end
    local text
    if format == "command" then
        local op = uint(buf, 0, "command", "opcode")
        local want = C.arguments_len[op]
        if OPCODE_NAMES[op] == nil then
            malformed(root, "unknown opcode " .. op .. " (the box answers unknown_opcode)")
        elseif op == C.opcode_stream_to then
            if body_len ~= 0 and body_len ~= C.destination_len then
                malformed(root, "stream-to arguments of " .. body_len
                    .. " bytes (0 or " .. C.destination_len .. ")")
            elseif body_len == C.destination_len and (buf(base + P.destination.ip[1], 4):uint() == 0
                or uint(buf, base, "destination", "port") == 0) then
                malformed(root, "stream-to destination IP 0.0.0.0 or port 0")
            end
        elseif body_len ~= want then
            malformed(root, string.format("%s arguments of %d bytes (%d)", OPCODE_NAMES[op],
                body_len, want))
        elseif body_len == 4 then
            local ticks = buf(base, 4):uint()
            if op == C.opcode_set_flush_timeout and (ticks < 1 or ticks > C.max_flush_timeout) then
                malformed(root, "flush timeout " .. ticks .. " outside 1..2^31-1 ticks")
            elseif op == C.opcode_set_status_period and ticks < C.min_status_period then
                malformed(root, "status period " .. ticks .. " below " .. C.min_status_period .. " ticks")
            end
        elseif op == C.opcode_cell_command then
            local port = uint(buf, base, "cell_command", "port")
            if port ~= C.all_ports and port >= C.max_ports then
                malformed(root, "cell command port " .. port .. " on no box")
            end
            if uint(buf, base, "cell_command", "reserved") ~= 0 then
                malformed(root, "cell command reserved bytes 1-3 not 0 (the box answers bad_argument)")
            end
            local fault = cell_command_fault(buf, base + P.cell_command.cell_packet[1])
            if fault ~= nil then
                malformed(root, fault)
            end
        end
        text = "command " .. (OPCODE_NAMES[op] or ("opcode " .. op)) .. ", seq " .. sequence
        if op == C.opcode_stream_to and body_len == C.destination_len then
            text = text .. " to " .. dissect_destination(buf, root, base)
        elseif op == C.opcode_cell_command and body_len == C.cell_command_len then
            for _, name in ipairs(ROWS.cell_command) do
                add(root, buf, base, "cell_command", name)
            end
        elseif body_len == 4 then
            root:add(F.command.ticks, buf(base, 4))
            text = text .. ": " .. buf(base, 4):uint() .. " ticks"
        end
    else
        if body_len < C.ack_fixed_len then
            root:add_proto_expert_info(E.malformed, "acknowledgement body shorter than "
                .. C.ack_fixed_len .. " bytes")
            pinfo.cols.info:set("skinbox: truncated acknowledgement")
            return len
        end
        for _, name in ipairs(ROWS.ack_body) do
            add(root, buf, base, "ack_body", name)
        end
        local op = uint(buf, base, "ack_body", "command_opcode")
        local result = uint(buf, base, "ack_body", "result")
        local port_count = uint(buf, 0, "ack", "port_count")
        if port_count < 1 or port_count > C.max_ports then
            malformed(root, "port count " .. port_count .. " outside 1.." .. C.max_ports)
        end
        if uint(buf, base, "ack_body", "body_reserved") ~= 0 then
            malformed(root, "acknowledgement body reserved bytes not 0")
        end
        local known = OPCODE_NAMES[op] ~= nil
        if RESULT_NAMES[result] == nil then
            malformed(root, "unknown result " .. result)
        elseif (known and result == C.result_unknown_opcode)
            or (not known and result ~= C.result_replay and result ~= C.result_other_box
                and result ~= C.result_unknown_opcode)
            or (result == C.result_downlink_full and op ~= C.opcode_cell_command) then
            malformed(root, "result " .. RESULT_NAMES[result] .. " is not one the box gives opcode " .. op)
        elseif result ~= C.result_replay and result ~= C.result_other_box
            and uint(buf, base, "ack_body", "last_accepted") ~= sequence then
            malformed(root, "last accepted is not the command's sequence number (result "
                .. RESULT_NAMES[result] .. " takes it)")
        end
        local reply_len = 0
        if result == C.result_ok and op == C.opcode_stream_to then
            reply_len = C.destination_len
        elseif result == C.result_ok and op == C.opcode_status_now then
            reply_len = C.box_counters_len
        end
        if body_len ~= C.ack_fixed_len + reply_len then
            malformed(root, string.format("body of %d bytes; opcode %d, result %d call for %d",
                body_len, op, result, C.ack_fixed_len + reply_len))
        end
        text = "ack " .. (OPCODE_NAMES[op] or ("opcode " .. op)) .. ", seq " .. sequence
            .. ": " .. (RESULT_NAMES[result] or ("result " .. result))
        local rest = base + C.ack_fixed_len
        if len - rest == C.destination_len then
            text = text .. ", streaming to " .. dissect_destination(buf, root, rest)
        elseif len - rest == C.box_counters_len then
            dissect_box_counters(buf, root, rest)
        end
    end
    root:append_text(": " .. text)
    pinfo.cols.info:set("box " .. box_id .. ": " .. text)
    return len
end

local function box_state(key)
    local s = boxes[key]
    if s == nil then
        s = { highest = nil, span = 0, seen = {}, boot_id = nil, cells = {} }
        boxes[key] = s
    end
    return s
end

-- The host client's sequence rules (host-client/src/sequence.rs): remember which of the
-- last WINDOW numbers below the highest arrived, with their base tick (a UInt64) as a tag;
-- a base tick more than RESTART_TAG_DROP below the highest one is a restarted box clock.
local WINDOW = C.sequence_window
local TWO32 = 4294967296
local RESTART_TAG_DROP = UInt64(C.restart_tag_drop)

local function seq_start(s, seq, tag)
    s.seen = {}
    s.highest = seq
    s.span = 0
    s.top_tag = tag
    s.seen[seq % WINDOW] = { seq = seq, tag = tag }
end

local function seq_push(s, seq, tag)
    if s.highest == nil then
        seq_start(s, seq, tag)
        return { kind = "first" }
    end
    if s.top_tag ~= nil then
        if s.top_tag > tag and s.top_tag - tag > RESTART_TAG_DROP then
            seq_start(s, seq, tag)
            return { kind = "restart" }
        end
        if tag > s.top_tag then
            s.top_tag = tag
        end
    else
        s.top_tag = tag
    end
    local ahead = (seq - s.highest) % TWO32
    local entry = s.seen[seq % WINDOW]
    if ahead == 0 then
        if entry ~= nil and entry.seq == seq and entry.tag ~= tag then
            seq_start(s, seq, tag)
            return { kind = "restart" }
        end
        return { kind = "duplicate" }
    end
    if ahead < TWO32 / 2 then
        if ahead >= WINDOW then
            s.seen = {}
        else
            for k = 1, ahead - 1 do
                s.seen[(s.highest + k) % WINDOW] = nil
            end
        end
        s.seen[seq % WINDOW] = { seq = seq, tag = tag }
        s.highest = seq
        s.span = s.span + ahead
        if ahead == 1 then
            return { kind = "in_order" }
        end
        return { kind = "gap", missing = ahead - 1 }
    end
    local behind = (s.highest - seq) % TWO32
    if behind >= WINDOW then
        seq_start(s, seq, nil)
        return { kind = "restart" }
    end
    if entry ~= nil and entry.seq == seq then
        if entry.tag ~= tag then
            seq_start(s, seq, tag)
            return { kind = "restart" }
        end
        return { kind = "duplicate" }
    end
    s.seen[seq % WINDOW] = { seq = seq, tag = tag }
    return { kind = "late", behind = behind }
end

-- Event sequence of one cell: packets skipped before this one (host-client decoder rules).
local function event_missing(s, cell_id, sequence)
    local last = s.cells[cell_id]
    local missing = 0
    if last ~= nil then
        local ahead = (sequence - last) % 65536
        if ahead > 1 and ahead < 32768 then
            missing = ahead - 1
        end
    end
    if last == nil or (sequence - last) % 65536 < 32768 then
        s.cells[cell_id] = sequence
    end
    return missing
end

local function channel_tree(tree, range, channel, raw)
    local f = F.channel[channel.name]
    local item = tree:add(f, range, raw * channel.units_per_lsb)
    item:append_text(" (raw " .. raw .. ")")
    tree:add(F.channel_raw[channel.name], range, raw):set_generated()
end

local function signed16(v)
    if v >= 32768 then
        return v - 65536
    end
    return v
end

local function dissect_cell(buf, base, tree, verdict, state)
    local header = uint(buf, base, "cell", "header")
    local cell_id = uint(buf, base, "cell", "cell_id")
    local kind
    if header == C.data_header then
        kind = "data"
    elseif header == C.event_header then
        kind = "event"
    end
    local cell_len = C.cell_packet_len
    local t = tree:add(F.record.cell_packet, buf(base, cell_len))
    t:set_text("Cell packet: " .. (kind or "unknown") .. ", cell " .. cell_id)
    add(t, buf, base, "cell", "header")
    add(t, buf, base, "cell", "cell_id")
    local summary = (kind or "unknown") .. " cell " .. cell_id
    if cell_id > C.max_cell_id then
        malformed(t, "cell id above 14 bits")
    end
    if kind == nil then
        t:add_proto_expert_info(E.malformed,
            string.format("unknown cell packet header 0x%02x", header))
    elseif kind == "data" then
        for _, ch in ipairs(CHANNELS) do
            local off, len = pos("data", ch.name)
            local range = buf(base + off, len)
            local raw = range:uint()
            if ch.signed then
                raw = range:int()
            end
            local di = t:add(F.data[ch.name], range)
            channel_tree(t, range, ch, raw)
            if ch.signed and (raw < C.accel_min or raw > C.accel_max) then
                malformed(di, ch.name .. " " .. raw .. " outside " .. C.accel_min .. ".." .. C.accel_max)
            end
        end
    else
        local mask_off, mask_len = pos("event", "mask")
        local mask_range = buf(base + mask_off, mask_len)
        local mask = mask_range:uint()
        local mt = t:add(F.event.mask, mask_range)
        for _, ch in ipairs(CHANNELS) do
            mt:add(F.mask[ch.name], mask_range)
        end
        mt:add(F.mask.second_part, mask_range)
        mt:add(F.mask.reserved, mask_range)
        if bit32.band(mask, C.mask_reserved) ~= 0 then
            mt:add_proto_expert_info(E.malformed, "reserved mask bits set")
        end
        local slot = 1
        local names = {}
        for _, ch in ipairs(CHANNELS) do
            if bit32.band(mask, bit32.lshift(1, ch.index)) ~= 0 then
                local name = "value_" .. slot
                if P.event[name] == nil then
                    mt:add_proto_expert_info(E.malformed, "more channels in the mask than value slots")
                    break
                end
                local off, len = pos("event", name)
                local range = buf(base + off, len)
                local raw = range:uint()
                if ch.signed then
                    raw = signed16(raw)
                end
                local vi = t:add(F.event[name], range)
                vi:append_text(" (" .. ch.name .. ")")
                if ch.signed and (raw < C.accel_min or raw > C.accel_max) then
                    malformed(vi, ch.name .. " " .. raw .. " outside " .. C.accel_min .. ".." .. C.accel_max)
                end
                channel_tree(t, range, ch, raw)
                names[#names + 1] = ch.name
                slot = slot + 1
            end
        end
        if #names == 0 then
            malformed(mt, "no channel in the mask")
        end
        while P.event["value_" .. slot] ~= nil do
            local ui = add(t, buf, base, "event", "value_" .. slot)
            if uint(buf, base, "event", "value_" .. slot) ~= 0 then
                malformed(ui, "value slot after the mask's channels is not 0")
            end
            slot = slot + 1
        end
        local sequence = uint(buf, base, "event", "sequence")
        add(t, buf, base, "event", "sequence")
        local second = bit32.band(mask, C.mask_second_part) ~= 0
        t:add(F.event_extra.second_part, mask_range, second):set_generated()
        if verdict.event_missing[base] == nil then
            verdict.event_missing[base] = event_missing(state, cell_id, sequence)
        end
        local missing = verdict.event_missing[base]
        t:add(F.event_extra.missing_before, missing):set_generated()
        if missing > 0 then
            t:add_proto_expert_info(E.event_gap, string.format(
                "%d event packets of cell %d missing before this one", missing, cell_id))
        end
        summary = summary .. " seq " .. sequence .. " [" .. table.concat(names, ",") .. "]"
        if second then
            summary = summary .. " (second part)"
        end
    end
    local end_byte = uint(buf, base, "cell", "end_of_packet")
    local ei = add(t, buf, base, "cell", "end_of_packet")
    if end_byte ~= skinbox.prefs.end_of_packet then
        ei:add_proto_expert_info(E.bad_end_byte, string.format(
            "end byte 0x%02x is not 0x%02x", end_byte, skinbox.prefs.end_of_packet))
    end
    return summary
end

local function dissect_records(buf, tree, header, verdict, state)
    local base_tick = buf(P.datagram.base_tick[1], P.datagram.base_tick[2]):uint64()
    local lo, hi
    for i = 0, header.entries - 1 do
        local base = C.header_len + i * C.record_len
        local port = uint(buf, base, "record", "port")
        local offset = buf(base + P.record.tick_offset[1], P.record.tick_offset[2]):int()
        local tick
        if offset >= 0 then
            tick = base_tick + offset
        else
            tick = base_tick - (-offset)
        end
        local rt = tree:add(F.record.record, buf(base, C.record_len))
        local pi = add(rt, buf, base, "record", "port")
        if port >= header.port_count then
            pi:add_proto_expert_info(E.malformed, string.format(
                "port %d is not below the box's port count %d", port, header.port_count))
        end
        local fi = add(rt, buf, base, "record", "flags")
        local flags_range = buf(base + P.record.flags[1], P.record.flags[2])
        fi:add(F.record_flags.loss_before, flags_range)
        local rflags = uint(buf, base, "record", "flags")
        if bit32.band(rflags, bit32.bnot(C.record_flags_defined)) ~= 0 then
            malformed(fi, string.format("undefined record flag bits 0x%02x", rflags))
        end
        add(rt, buf, base, "record", "tick_offset")
        rt:add(F.record_extra.tick, buf(base + P.record.tick_offset[1], P.record.tick_offset[2]),
            tick):set_generated()
        rt:add(F.record_extra.time, buf(base + P.record.tick_offset[1], P.record.tick_offset[2]),
            tick:tonumber() * C.tick_ns / 1e9):set_generated()
        local cell_base = base + P.record.cell_packet[1]
        local summary = dissect_cell(buf, cell_base, rt, verdict, state)
        rt:set_text(string.format("Record %d: port %d, tick %s, %s", i + 1, port,
            tostring(tick), summary))
        if lo == nil or port < lo then lo = port end
        if hi == nil or port > hi then hi = port end
    end
    local ports = ""
    if lo ~= nil then
        if lo == hi then
            ports = ", port " .. lo
        else
            ports = ", ports " .. lo .. "-" .. hi
        end
    end
    local noun = " records"
    if header.entries == 1 then
        noun = " record"
    end
    local text = header.entries .. noun .. ports .. ", seq " .. header.sequence
    if bit32.band(header.flags, C.flag_flush_timeout) ~= 0 then
        text = text .. ", flush timeout"
    end
    return text
end

local function dissect_status(buf, tree, header, verdict, state)
    local base = C.header_len
    local st = tree:add(F.status.status, buf(base, C.status_fixed_len))
    local boot_id = uint(buf, base, "status", "boot_id")
    for _, name in ipairs({ "boot_id", "datagrams_sent", "records_sent", "first_port",
        "reserved" }) do
        add(st, buf, base, "status", name)
    end
    local first_port = uint(buf, base, "status", "first_port")
    if bit32.band(header.flags, C.flag_time_syncs) ~= 0 then
        st:append_text(" (the box sends time syncs)")
    end
    if verdict.reset then
        st:add_proto_expert_info(E.box_reset, string.format(
            "box reset: boot id 0x%08x, was 0x%08x", boot_id, verdict.reset))
    end
    for i = 0, header.entries - 1 do
        local b = base + C.status_fixed_len + i * C.port_counters_len
        local port = first_port + i
        local pt = tree:add(F.port_counters.block, buf(b, C.port_counters_len))
        pt:add(F.port_counters.port, port):set_generated()
        local lost = 0
        for _, counter in ipairs(COUNTERS) do
            add(pt, buf, b, "port_counters", counter.name)
            if counter.loss then
                lost = lost + uint(buf, b, "port_counters", counter.name)
            end
        end
        pt:set_text(string.format("Port %d: %d good, %d lost", port,
            uint(buf, b, "port_counters", "packets_good"), lost))
        if port >= header.port_count then
            malformed(pt, string.format("counter block of port %d, at or above the port count %d",
                port, header.port_count))
        end
    end
    local text = "status, seq " .. header.sequence
    if header.entries > 0 then
        text = text .. ", ports " .. first_port .. "-" .. (first_port + header.entries - 1)
    end
    return text .. string.format(", boot 0x%08x", boot_id)
end

local function dissect(buf, pinfo, tree)
    local len = buf:len()
    pinfo.cols.protocol = "skinbox"
    local root = tree:add(skinbox, buf())
    if len < C.header_len then
        root:add_proto_expert_info(E.malformed, string.format(
            "%d bytes: shorter than the %d-byte header", len, C.header_len))
        pinfo.cols.info:set("skinbox: truncated")
        return len
    end
    local header = {
        version = uint(buf, 0, "datagram", "version"),
        kind = uint(buf, 0, "datagram", "kind"),
        box_id = uint(buf, 0, "datagram", "box_id"),
        port_count = uint(buf, 0, "datagram", "port_count"),
        flags = uint(buf, 0, "datagram", "flags"),
        sequence = uint(buf, 0, "datagram", "sequence"),
        base_tick = buf(P.datagram.base_tick[1], P.datagram.base_tick[2]):uint64(),
        entries = uint(buf, 0, "datagram", "entry_count"),
    }
    add(root, buf, 0, "datagram", "magic")
    local vi = add(root, buf, 0, "datagram", "version")
    if header.version ~= C.version then
        vi:add_proto_expert_info(E.unknown_version, string.format(
            "version %d: this dissector reads version %d", header.version, C.version))
        pinfo.cols.info:set("skinbox: unknown version " .. header.version)
        return len
    end
    if header.kind == C.kind_command or header.kind == C.kind_ack then
        return dissect_control(buf, pinfo, root, header.kind)
    end
    local ki = add(root, buf, 0, "datagram", "kind")
    add(root, buf, 0, "datagram", "box_id")
    add(root, buf, 0, "datagram", "port_count")
    local fi = add(root, buf, 0, "datagram", "flags")
    local flags_range = buf(P.datagram.flags[1], P.datagram.flags[2])
    fi:add(F.flags.flush_timeout, flags_range)
    fi:add(F.flags.box_counters, flags_range)
    fi:add(F.flags.reserved, flags_range)
    local si = add(root, buf, 0, "datagram", "sequence")
    add(root, buf, 0, "datagram", "base_tick")
    add(root, buf, 0, "datagram", "entry_count")
    add(root, buf, 0, "datagram", "reserved")

    local expected = datagram_len(header.kind, header.entries, header.flags)
    if expected == nil then
        ki:add_proto_expert_info(E.malformed, "unknown datagram kind " .. header.kind)
        pinfo.cols.info:set("skinbox: unknown kind " .. header.kind)
        return len
    end
    if header.entries > max_entries(header.kind, header.flags) or len ~= expected then
        root:add_proto_expert_info(E.malformed, string.format(
            "%d bytes, but %d entries make %d bytes (at most %d entries)", len,
            header.entries, expected, max_entries(header.kind, header.flags)))
        pinfo.cols.info:set("skinbox: length does not match the entry count")
        return len
    end

    if header.port_count < 1 or header.port_count > C.max_ports then
        malformed(root, "port count " .. header.port_count .. " outside 1.." .. C.max_ports)
    end
    local defined = C.flags_defined_status
    if header.kind == C.kind_records then
        defined = C.flags_defined_records
    end
    if bit32.band(header.flags, bit32.bnot(defined)) ~= 0 then
        malformed(fi, string.format("undefined flag bits 0x%02x",
            bit32.band(header.flags, bit32.bnot(defined))))
    end

    -- a box is its box id and its source address (IP and UDP port), as in the host client
    local key = header.box_id .. "@" .. tostring(pinfo.src) .. ":" .. pinfo.src_port
    local state = box_state(key)
    local verdict = verdicts[pinfo.number]
    if verdict == nil or not pinfo.visited then
        verdict = { event_missing = {}, reset = false }
        local tag = header.base_tick
        local boot_id = nil
        if header.kind ~= C.kind_records then
            boot_id = uint(buf, C.header_len, "status", "boot_id")
        end
        if boot_id ~= nil and state.boot_id ~= nil and state.boot_id ~= boot_id then
            -- The box numbers its datagrams from its reset on: go on from this status
            -- datagram, unless the numbering already restarted just before it.
            verdict.reset = state.boot_id
            local ahead = nil
            if state.highest ~= nil then
                ahead = (header.sequence - state.highest) % TWO32
            end
            if ahead ~= nil and ahead >= 1 and ahead < WINDOW then
                verdict.sequence = seq_push(state, header.sequence, tag)
            else
                seq_start(state, header.sequence, tag)
                verdict.sequence = { kind = "first" }
            end
        else
            verdict.sequence = seq_push(state, header.sequence, tag)
        end
        if boot_id ~= nil then
            state.boot_id = boot_id
        end
        verdicts[pinfo.number] = verdict
    end
    local v = verdict.sequence
    if v.kind == "gap" then
        root:add(F.datagram_extra.missing_before, v.missing):set_generated()
        si:add_proto_expert_info(E.sequence_gap, string.format(
            "%d datagrams missing before this one", v.missing))
    else
        root:add(F.datagram_extra.missing_before, 0):set_generated()
    end
    if v.kind == "late" then
        si:add_proto_expert_info(E.sequence_late, string.format(
            "late datagram: %d behind the highest sequence number", v.behind))
    elseif v.kind == "duplicate" then
        si:add_proto_expert_info(E.sequence_duplicate)
    elseif v.kind == "restart" then
        si:add_proto_expert_info(E.sequence_restart,
            "sequence numbering restarted (a box reset before its status report?)")
    end

    local text
    if header.kind == C.kind_records then
        text = dissect_records(buf, root, header, verdict, state)
    else
        text = dissect_status(buf, root, header, verdict, state)
        if bit32.band(header.flags, C.flag_box_counters) ~= 0 then
            dissect_box_counters(buf, root, len - C.box_counters_len)
        end
    end
    root:append_text(": " .. text)
    pinfo.cols.info:set("box " .. header.box_id .. ": " .. text)
    return len
end

function skinbox.dissector(buf, pinfo, tree)
    return dissect(buf, pinfo, tree)
end

-- Claims a UDP payload on any port when it is a whole version-1 datagram.
local function heuristic(buf, pinfo, tree)
    local len = buf:len()
    if len < C.header_len or buf(P.datagram.magic[1], P.datagram.magic[2]):string() ~= C.magic then
        return false
    end
    if uint(buf, 0, "datagram", "version") ~= C.version then
        return false
    end
    local kind = uint(buf, 0, "datagram", "kind")
    if kind == C.kind_command or kind == C.kind_ack then
        -- the command header's length field sits where a box datagram has its entry count
        if len ~= C.header_len + uint(buf, 0, "command", "argument_length") then
            return false
        end
    elseif len ~= datagram_len(kind, uint(buf, 0, "datagram", "entry_count"),
        uint(buf, 0, "datagram", "flags")) then
        return false
    end
    dissect(buf, pinfo, tree)
    return true
end

local udp_port = skinbox.prefs.udp_port
DissectorTable.get("udp.port"):add(udp_port, skinbox)
skinbox:register_heuristic("udp", heuristic)

function skinbox.prefs_changed()
    if udp_port ~= skinbox.prefs.udp_port then
        DissectorTable.get("udp.port"):remove(udp_port, skinbox)
        udp_port = skinbox.prefs.udp_port
        DissectorTable.get("udp.port"):add(udp_port, skinbox)
    end
end
