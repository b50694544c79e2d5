// tactile-watch: a minimal viewer of a tactile server in Go, the example of a
// client in a language the project does not ship (proto/README.md, "A client
// in another language"). It says Hello (as a viewer, or a controller, which
// also gets the states, with -role Controller), reads the Welcome and the
// SceneDescription, then prints one JSON line per message it reads: the scene
// and each StateFrame's time, vertex count and largest displacement from the
// rest surface.
//
//	go run ./cmd/tactile-watch -url ws://127.0.0.1:8765/ -token TOKEN -states 30
//
// Exit status: 0 after -states state frames, 1 on an Error from the server or
// a message it cannot read, 2 on bad flags.
package main

import (
	"encoding/json"
	"errors"
	"flag"
	"fmt"
	"math"
	"net/http"
	"net/url"
	"os"
	"time"

	flatbuffers "github.com/google/flatbuffers/go"
	"github.com/gorilla/websocket"

	"tactile.example/proto/tactile/proto"
)

// fileIdentifier is what every tactile message carries at bytes 4-7
// (tactile.fbs: file_identifier "TCTL"); the server refuses a buffer without it.
const fileIdentifier = "TCTL"

// hello is the first message a client sends: the protocol it speaks, its role
// and the server's token.
func hello(token string, role proto.Role) []byte {
	b := flatbuffers.NewBuilder(256)
	name := b.CreateString("tactile-watch (Go)")
	tok := b.CreateString(token)
	proto.HelloStart(b)
	proto.HelloAddProtocolMajor(b, uint16(proto.ProtocolMajorCurrent))
	proto.HelloAddProtocolMinor(b, uint16(proto.ProtocolMinorCurrent))
	proto.HelloAddRole(b, role)
	proto.HelloAddToken(b, tok)
	proto.HelloAddClientName(b, name)
	h := proto.HelloEnd(b)
	proto.EnvelopeStart(b)
	proto.EnvelopeAddMessageType(b, proto.MessageHello)
	proto.EnvelopeAddMessage(b, h)
	b.FinishWithFileIdentifier(proto.EnvelopeEnd(b), []byte(fileIdentifier))
	return b.FinishedBytes()
}

// envelope reads a message's root, after checking its size and identifier.
// The Go runtime has no verifier: a damaged buffer can make an accessor read
// out of bounds, which panics; read() turns that into an error.
func envelope(raw []byte) (*proto.Envelope, error) {
	if len(raw) < 8 || string(raw[4:8]) != fileIdentifier {
		return nil, fmt.Errorf("not a tactile message: %d bytes without the file identifier %q", len(raw), fileIdentifier)
	}
	return proto.GetRootAsEnvelope(raw, 0), nil
}

type watcher struct {
	out   *json.Encoder
	rest  []float32 // the rest surface (n_vertices x 3) of the scene being watched [m]
	scene uint32
}

// read turns one message into the line it prints.
func (w *watcher) read(raw []byte) (line map[string]any, err error) {
	defer func() {
		if r := recover(); r != nil {
			err = fmt.Errorf("damaged message (%d bytes): %v", len(raw), r)
		}
	}()
	e, err := envelope(raw)
	if err != nil {
		return nil, err
	}
	var t flatbuffers.Table
	if !e.Message(&t) {
		return nil, errors.New("an envelope without a message")
	}
	switch e.MessageType() {
	case proto.MessageWelcome:
		var m proto.Welcome
		m.Init(t.Bytes, t.Pos)
		return map[string]any{"type": "welcome", "role": m.Role().String(), "server": string(m.ServerName()),
			"protocol": fmt.Sprintf("%d.%d", m.ProtocolMajor(), m.ProtocolMinor()), "session_id": m.SessionId()}, nil
	case proto.MessageError:
		var m proto.Error
		m.Init(t.Bytes, t.Pos)
		return map[string]any{"type": "error", "code": m.Code().String(), "message": string(m.Message())}, nil
	case proto.MessageSceneDescription:
		var m proto.SceneDescription
		m.Init(t.Bytes, t.Pos)
		w.scene = m.SceneId()
		w.rest = make([]float32, m.RestPositionsLength())
		for i := range w.rest {
			w.rest[i] = m.RestPositions(i)
		}
		proxies := []string{}
		var p proto.ProxyInfo
		for j := 0; j < m.ProxiesLength(); j++ {
			if m.Proxies(&p, j) {
				proxies = append(proxies, string(p.Name()))
			}
		}
		return map[string]any{"type": "scene", "scene": string(m.SceneName()), "scene_id": m.SceneId(),
			"vertices": len(w.rest) / 3, "triangles": m.TrianglesLength() / 3, "proxies": proxies}, nil
	case proto.MessageStateFrame:
		var m proto.StateFrame
		m.Init(t.Bytes, t.Pos)
		n := m.PositionsLength()
		line := map[string]any{"type": "state", "scene_id": m.SceneId(), "step": m.Step(), "sim_time_s": m.SimTime(),
			"vertices": n / 3}
		if m.SceneId() == w.scene && n == len(w.rest) {
			largest := 0.0
			for v := 0; v+2 < n; v += 3 {
				dx := float64(m.Positions(v) - w.rest[v])
				dy := float64(m.Positions(v+1) - w.rest[v+1])
				dz := float64(m.Positions(v+2) - w.rest[v+2])
				largest = math.Max(largest, math.Sqrt(dx*dx+dy*dy+dz*dz))
			}
			line["max_displacement_m"] = largest
		}
		return line, nil
	default:
		return map[string]any{"type": e.MessageType().String()}, nil
	}
}

func main() {
	address := flag.String("url", "ws://127.0.0.1:8765/", "the server's WebSocket address")
	token := flag.String("token", os.Getenv("TACTILE_TOKEN"), "the server's token (default: $TACTILE_TOKEN)")
	states := flag.Int("states", 30, "state frames to read before closing")
	timeout := flag.Duration("timeout", 20*time.Second, "give up after this long")
	roleName := flag.String("role", "Viewer", "the role to ask for: Viewer or Controller (which needs the token)")
	flag.Parse()
	role, known := proto.EnumValuesRole[*roleName]
	if !known || (role != proto.RoleViewer && role != proto.RoleController) {
		fmt.Fprintf(os.Stderr, "tactile-watch: -role %q: Viewer or Controller\n", *roleName)
		os.Exit(2)
	}
	if *states < 1 {
		fmt.Fprintln(os.Stderr, "tactile-watch: -states must be at least 1")
		os.Exit(2)
	}
	if _, err := url.Parse(*address); err != nil {
		fmt.Fprintln(os.Stderr, "tactile-watch: -url:", err)
		os.Exit(2)
	}
	os.Exit(run(*address, *token, role, *states, *timeout))
}

func run(address, token string, role proto.Role, states int, timeout time.Duration) int {
	dialer := websocket.Dialer{HandshakeTimeout: 5 * time.Second}
	conn, _, err := dialer.Dial(address, http.Header{})
	if err != nil {
		fmt.Fprintln(os.Stderr, "tactile-watch: connect:", err)
		return 1
	}
	defer conn.Close()
	conn.SetReadLimit(64 << 20)
	if err := conn.WriteMessage(websocket.BinaryMessage, hello(token, role)); err != nil {
		fmt.Fprintln(os.Stderr, "tactile-watch: send Hello:", err)
		return 1
	}
	w := watcher{out: json.NewEncoder(os.Stdout)}
	deadline := time.Now().Add(timeout)
	for seen := 0; seen < states; {
		_ = conn.SetReadDeadline(deadline)
		kind, raw, err := conn.ReadMessage()
		if err != nil {
			fmt.Fprintln(os.Stderr, "tactile-watch: read:", err)
			return 1
		}
		if kind != websocket.BinaryMessage {
			continue
		}
		line, err := w.read(raw)
		if err != nil {
			fmt.Fprintln(os.Stderr, "tactile-watch:", err)
			return 1
		}
		_ = w.out.Encode(line)
		switch line["type"] {
		case "error":
			return 1
		case "state":
			seen++
		}
	}
	_ = conn.WriteControl(websocket.CloseMessage, websocket.FormatCloseMessage(websocket.CloseNormalClosure, "done"),
		time.Now().Add(time.Second))
	return 0
}
