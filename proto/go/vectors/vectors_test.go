// The Go bindings read the golden vectors (proto/vectors/) as the C++,
// Python and JavaScript codecs do: every vector carries the identifier and
// the message type its JSON names, and typed accessors see the written values.
package vectors_test

import (
	"encoding/json"
	"os"
	"path/filepath"
	"strings"
	"testing"

	flatbuffers "github.com/google/flatbuffers/go"

	"tactile.example/proto/tactile/proto"
)

type vector struct {
	MessageType string         `json:"message_type"`
	Message     map[string]any `json:"message"`
}

func load(t *testing.T, name string) ([]byte, vector) {
	t.Helper()
	raw, err := os.ReadFile(filepath.Join("..", "..", "vectors", name+".tctl"))
	if err != nil {
		t.Fatal(err)
	}
	text, err := os.ReadFile(filepath.Join("..", "..", "vectors", name+".json"))
	if err != nil {
		t.Fatal(err)
	}
	var v vector
	if err := json.Unmarshal(text, &v); err != nil {
		t.Fatalf("%s.json: %v", name, err)
	}
	return raw, v
}

func TestEveryVectorHasTheIdentifierAndItsMessageType(t *testing.T) {
	files, _ := filepath.Glob(filepath.Join("..", "..", "vectors", "*.tctl"))
	if len(files) < 20 {
		t.Fatalf("%d vectors found", len(files))
	}
	for _, f := range files {
		name := strings.TrimSuffix(filepath.Base(f), ".tctl")
		raw, v := load(t, name)
		if string(raw[4:8]) != "TCTL" {
			t.Errorf("%s: identifier %q", name, raw[4:8])
		}
		if got := proto.GetRootAsEnvelope(raw, 0).MessageType().String(); got != v.MessageType {
			t.Errorf("%s: message type %s, the JSON says %s", name, got, v.MessageType)
		}
	}
}

func TestStateFrameReadsAsWritten(t *testing.T) {
	raw, v := load(t, "state_frame")
	var tab flatbuffers.Table
	if !proto.GetRootAsEnvelope(raw, 0).Message(&tab) {
		t.Fatal("no message")
	}
	var m proto.StateFrame
	m.Init(tab.Bytes, tab.Pos)
	if m.SimTime() != v.Message["sim_time"].(float64) || float64(m.Step()) != v.Message["step"].(float64) {
		t.Errorf("sim_time %v step %v", m.SimTime(), m.Step())
	}
	want := v.Message["positions"].([]any)
	if m.PositionsLength() != len(want) {
		t.Fatalf("%d positions, want %d", m.PositionsLength(), len(want))
	}
	for i, w := range want {
		if m.Positions(i) != float32(w.(float64)) {
			t.Errorf("positions[%d] = %v, want %v", i, m.Positions(i), w)
		}
	}
}

func TestHelloReadsAsWritten(t *testing.T) {
	raw, v := load(t, "hello")
	var tab flatbuffers.Table
	if !proto.GetRootAsEnvelope(raw, 0).Message(&tab) {
		t.Fatal("no message")
	}
	var m proto.Hello
	m.Init(tab.Bytes, tab.Pos)
	if m.Role().String() != v.Message["role"] || string(m.Token()) != v.Message["token"] {
		t.Errorf("role %s token %q", m.Role(), m.Token())
	}
	devices := v.Message["devices"].([]any)
	if m.DevicesLength() != len(devices) || string(m.Devices(1)) != devices[1] {
		t.Errorf("devices %d", m.DevicesLength())
	}
	if float64(m.MaxRateHz()) != v.Message["max_rate_hz"] { // (1.10)
		t.Errorf("max_rate_hz %v", m.MaxRateHz())
	}
}

func TestHapticFrameCarriesTheLocalModels(t *testing.T) {
	raw, v := load(t, "haptic_frame")
	var tab flatbuffers.Table
	if !proto.GetRootAsEnvelope(raw, 0).Message(&tab) {
		t.Fatal("no message")
	}
	var m proto.HapticFrame
	m.Init(tab.Bytes, tab.Pos)
	want := v.Message["device_models"].([]any) // (1.11)
	if m.DeviceModelsLength() != len(want) {
		t.Fatalf("%d device models, want %d", m.DeviceModelsLength(), len(want))
	}
	for i, w := range want {
		var dm proto.DeviceModel
		if !m.DeviceModels(&dm, i) {
			t.Fatalf("device_models[%d] missing", i)
		}
		mw := w.(map[string]any)
		if dm.ReleaseM() != float32(mw["release_m"].(float64)) || dm.RadiusM() != float32(mw["radius_m"].(float64)) {
			t.Errorf("device_models[%d]: release %v radius %v", i, dm.ReleaseM(), dm.RadiusM())
		}
		n := mw["normal"].(map[string]any)
		if dm.Normal(nil).Y() != float32(n["y"].(float64)) {
			t.Errorf("device_models[%d]: normal y %v", i, dm.Normal(nil).Y())
		}
		d := mw["damping"].(map[string]any)
		if dm.Damping(nil).M12() != float32(d["m12"].(float64)) {
			t.Errorf("device_models[%d]: damping m12 %v", i, dm.Damping(nil).M12())
		}
	}
}
